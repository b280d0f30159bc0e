#!/bin/sh
# PID 1 of the camera test VM (scripts/camera_vm_test.sh bakes it into the root filesystem as
# /sbin/so101-vm-init). The root filesystem stays read-only: everything is written to tmpfs.
# Unpacks the payload (a tar on the second disk), runs its run.sh, writes its results as a tar
# onto the third disk, and powers the VM off. Its output goes to the serial console.
# Debian's initramfs has moved /sys and /dev here already.
mountpoint -q /proc || mount -t proc proc /proc
mountpoint -q /sys || mount -t sysfs sysfs /sys
mountpoint -q /dev || mount -t devtmpfs devtmpfs /dev
mkdir -p /dev/pts /dev/shm
mount -t devpts devpts /dev/pts
mount -t tmpfs tmpfs /dev/shm
mount -t tmpfs tmpfs /tmp
mount -t tmpfs tmpfs /run
# DDS needs an interface with multicast: loopback only (the VM has no network card).
ip link set lo up
ip link set lo multicast on
ip route add 224.0.0.0/4 dev lo

mkdir -p /tmp/payload /tmp/out
if tar -xf /dev/vdb -C /tmp/payload; then
    echo "so101-vm: payload unpacked, running it"
    /tmp/payload/run.sh /tmp/payload /tmp/out 2>&1 | tee /tmp/out/guest.log
    echo "so101-vm: payload done"
else
    echo "so101-vm: ERROR: no payload on /dev/vdb" | tee /tmp/out/guest.log
fi
tar -cf /dev/vdc -C /tmp/out .
sync
echo "so101-vm: powering off"
echo o >/proc/sysrq-trigger
sleep 60
