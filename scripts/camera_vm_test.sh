#!/usr/bin/env bash
# The camera node on a real kernel V4L2 driver: boots a small Debian VM (debootstrap, Debian's
# kernel, qemu, no network card), loads the kernel's virtual video test driver `vivid` there, runs
# the shipped so101_camera_node with the shipped recorder_node as its subscriber, and checks what
# they did against the driver's own tool, v4l2-ctl, in the same VM (tests/vm/test_vivid.py).
#
#   scripts/camera_vm_test.sh [PYTEST_ARGS...]
#
# .ci/run runs it after the suite. The root filesystem (about 700 MB) is built once and cached in
# ~/.cache/so101/vm, keyed on the Debian release and this script's package list and init; the
# nodes are copied in on every run. KVM is used where the host CPU has hardware virtualization
# (vmx or svm); elsewhere qemu emulates the CPU (TCG): a few minutes per run.
#
# Environment: SO101_VM_SUITE (Debian release of the VM, default bookworm: its C library must be
# at least as new as the one the nodes were built against), SO101_VM_MIRROR (Debian mirror),
# SO101_VM_ACCEL (kvm or tcg, to override the choice), SO101_VM_RESULTS (keep the results there).
# Needs root or sudo (debootstrap, apt-get) the first time.
set -euo pipefail

. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
help_if_asked "${BASH_SOURCE[0]}" "$@"
cd "${SO101_ROOT}"

log() { printf '\033[1mcamera-vm:\033[0m %s\n' "$*" >&2; }
die() { printf 'camera-vm: ERROR: %s\n' "$*" >&2; exit 1; }

suite="${SO101_VM_SUITE:-bookworm}"
mirror="${SO101_VM_MIRROR:-http://deb.debian.org/debian}"
# The guest's packages: Debian's kernel (with vivid as a module), v4l2-ctl, modprobe, ip.
guest_packages=linux-image-amd64,v4l-utils,kmod,iproute2,initramfs-tools

sudo_cmd=()
[ "$(id -u)" = 0 ] || sudo_cmd=(sudo)
host_packages=(qemu-system-x86 debootstrap e2fsprogs)
missing=()
for package in "${host_packages[@]}"; do
    dpkg-query -W -f='${Status}' "${package}" 2>/dev/null | grep -q 'ok installed' || missing+=("${package}")
done
if [ "${#missing[@]}" -gt 0 ]; then
    log "installing ${missing[*]}"
    "${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}" >/dev/null
fi

# The root filesystem, built once per key: a read-only ext4 image, the kernel and its initrd.
key="$(printf '%s\n' "${suite}" "${guest_packages}" | cat - scripts/vm/guest_init.sh | sha256sum | cut -c1-16)"
image_dir="${HOME}/.cache/so101/vm/${suite}-${key}"
if [ ! -f "${image_dir}/root.img" ]; then
    log "building the VM's root filesystem (Debian ${suite}, once: a few minutes)"
    work="$(mktemp -d "${TMPDIR:-/tmp}/so101-vm-root.XXXXXX")"
    trap 'rm -rf "${work}"' EXIT
    "${sudo_cmd[@]}" debootstrap --variant=minbase --include="${guest_packages}" \
        "${suite}" "${work}/root" "${mirror}" >"${work}/debootstrap.log" 2>&1 \
        || { tail -20 "${work}/debootstrap.log" >&2; die "debootstrap failed"; }
    "${sudo_cmd[@]}" install -m 0755 scripts/vm/guest_init.sh "${work}/root/sbin/so101-vm-init"
    "${sudo_cmd[@]}" rm -rf "${work}/root/var/cache/apt/archives"/*.deb "${work}/root/usr/share/doc"
    mkdir -p "${work}/image"
    "${sudo_cmd[@]}" cp "${work}/root/boot"/vmlinuz-* "${work}/image/vmlinuz"
    "${sudo_cmd[@]}" cp "${work}/root/boot"/initrd.img-* "${work}/image/initrd.img"
    "${sudo_cmd[@]}" mkfs.ext4 -q -L so101-vm -d "${work}/root" "${work}/image/root.img" 1200M
    "${sudo_cmd[@]}" chown -R "$(id -u):$(id -g)" "${work}/image"
    mkdir -p "$(dirname "${image_dir}")"
    rm -rf "${image_dir}"
    mv "${work}/image" "${image_dir}"
    "${sudo_cmd[@]}" rm -rf "${work}"
    trap - EXIT
fi

# The nodes under test, as the suite built them.
# (the workspace build of scripts/setup.sh: nothing to do after the suite; a build of just these
# two packages would resolve features apart and compile for a minute.)
log "building so101_camera_node and recorder_node"
cargo build --release --locked --workspace >/dev/null 2>&1 || cargo build --release --locked --workspace
run_dir="$(mktemp -d "${TMPDIR:-/tmp}/so101-vm-run.XXXXXX")"
trap 'rm -rf "${run_dir}"' EXIT
mkdir -p "${run_dir}/payload/bin"
cp "${CARGO_TARGET_DIR}/release/so101_camera_node" "${CARGO_TARGET_DIR}/release/recorder_node" "${run_dir}/payload/bin/"
install -m 0755 scripts/vm/vivid_guest.sh "${run_dir}/payload/run.sh"
tar -cf "${run_dir}/payload.tar" -C "${run_dir}/payload" .
truncate -s 256M "${run_dir}/results.img"

accel=tcg
if [ -w /dev/kvm ] && grep -qE '\b(vmx|svm)\b' /proc/cpuinfo; then accel=kvm; fi
accel="${SO101_VM_ACCEL:-${accel}}"
log "booting the VM (${accel}; without KVM this takes a few minutes)"
started=${SECONDS}
# No network card (-nic none), and qemu itself in a namespace with only loopback. The guest
# powers off when done; a VM that hangs is stopped after 15 minutes.
scripts/isolated timeout 900 qemu-system-x86_64 -accel "${accel}" -machine q35 -cpu max -smp 2 -m 1536 \
    -nographic -no-reboot -nic none \
    -kernel "${image_dir}/vmlinuz" -initrd "${image_dir}/initrd.img" \
    -append "console=ttyS0 root=/dev/vda ro init=/sbin/so101-vm-init panic=-1 quiet" \
    -drive "file=${image_dir}/root.img,if=virtio,format=raw,snapshot=on" \
    -drive "file=${run_dir}/payload.tar,if=virtio,format=raw,readonly=on" \
    -drive "file=${run_dir}/results.img,if=virtio,format=raw" \
    </dev/null >"${run_dir}/console.log" 2>&1 \
    || { tail -30 "${run_dir}/console.log" >&2; die "qemu failed"; }
log "VM done in $((SECONDS - started)) s"

results="${SO101_VM_RESULTS:-${run_dir}/results}"
mkdir -p "${results}"
tar -xf "${run_dir}/results.img" -C "${results}" \
    || { tail -30 "${run_dir}/console.log" >&2; die "the VM left no results"; }
cp "${run_dir}/console.log" "${results}/console.log"
printf '%s\n' "${accel}" >"${results}/accel.txt"
printf '%s\n' "$((SECONDS - started))" >"${results}/vm-seconds.txt"

log "checking the results (tests/vm)"
SO101_VIVID_RESULTS="${results}" .venv/bin/python -m pytest -q tests/vm "$@"
