#!/bin/bash
# The camera node against the kernel's virtual video test driver (vivid), inside the test VM:
# run by scripts/vm/guest_init.sh as PAYLOAD/run.sh PAYLOAD OUT. It only gathers evidence (the
# driver's own view through v4l2-ctl, the node's output, a bag recorded by the shipped
# recorder_node); tests/vm/test_vivid.py judges it on the host.
#
# Timeline (wall clock of each step in OUT/events.txt): vivid loaded; modes listed by v4l2-ctl
# and by the node; the driver's own streaming rate (v4l2-ctl, no node running); the node started
# with a gain control while the recorder records its topics; vivid's Disconnect control; three
# frames marked damaged; the driver unbound and bound again; both stopped; a camera that is not
# there.
set -u
payload="$1"
out="$2"
bin="${payload}/bin"
device=/dev/video0
width=320
height=180
fps=15
gain=10

event() { printf '%s %s\n' "$(date +%s.%N)" "$*" >>"${out}/events.txt"; echo "vivid_guest: $*"; }
ctl() { v4l2-ctl -d "${device}" "$@"; }

uname -r >"${out}/kernel.txt"
export CPU_FILE="${out}/node-cpu.txt"
"${bin}/so101_camera_node" --version >"${out}/node-version.txt" 2>&1 || {
    echo "vivid_guest: the node does not run in the VM (built for a newer C library?)"
    exit 1
}

# One vivid instance with its default device nodes: video capture, output, VBI, radio, SDR,
# metadata and touch nodes; /dev/video0 is its video capture node (webcam input).
modprobe vivid n_devs=1 || exit 1
for _ in $(seq 50); do [ -e "${device}" ] && break; sleep 0.1; done
event "vivid loaded"
v4l2-ctl --list-devices >"${out}/list-devices.txt" 2>&1
for node in /dev/video*; do
    printf '%s\n' "${node}" >>"${out}/nodes.txt"
    v4l2-ctl -d "${node}" --info >"${out}/info-${node##*/}.txt" 2>&1
done
ctl --list-formats-ext >"${out}/formats-ext.txt" 2>&1
ctl --list-ctrls-menus >"${out}/controls.txt" 2>&1
"${bin}/so101_camera_node" --list >"${out}/node-list-all.txt" 2>&1
"${bin}/so101_camera_node" --list --camera "top=${device}" >"${out}/node-list.txt" 2>&1

# A still colour-bar pattern: no text over it (osd_text_mode 2 = none), so every frame of the
# node and the driver's own raw frame show the same picture.
ctl -c osd_text_mode=2
ctl --set-fmt-video="width=${width},height=${height},pixelformat=YUYV" --set-parm="${fps}" >/dev/null
ctl --stream-mmap --stream-skip=5 --stream-count=1 --stream-to="${out}/frame.yuyv"

# The driver's rate with nothing else running: v4l2-ctl streams 150 frames.
event "v4l2-ctl stream start"
ctl --stream-mmap --stream-count=150 --stream-to=/dev/null >"${out}/v4l2-stream.txt" 2>&1
event "v4l2-ctl stream end"
ctl --get-ctrl=gain,gain_automatic >"${out}/controls-before.txt" 2>&1

# The node (asked for 320x180 at 30 frames/s and a gain) and the recorder as its subscriber.
"${bin}/recorder_node" --output "${out}/bags" --start --duration 75 \
    --topics /camera/top/image_raw/compressed,/camera/top/camera_info,/diagnostics \
    >"${out}/recorder.log" 2>&1 &
recorder=$!
sleep 3
event "node start"
# The CPU time it used (its shell's `times`, children's line) goes to node-cpu.txt.
bash -c '"$@"; status=$?; times >"${CPU_FILE}"; exit "${status}"' node \
    "${bin}/so101_camera_node" --camera "top=${device}:${width}x${height}@${fps}" \
    --control "top.gain=${gain}" --duration 65 >"${out}/node.log" 2>&1 &
node=$!
sleep 20
event "node steady"
ctl --get-ctrl=gain,gain_automatic >"${out}/controls-running.txt" 2>&1

# Behind the node's back: another gain, then vivid's Disconnect (an unplug that ends when every
# open handle is closed). The node must reopen the camera and set its gain again.
ctl -c gain=50
event "disconnect"
ctl -c disconnect=1
sleep 12
event "after disconnect"
ctl --get-ctrl=gain,gain_automatic >"${out}/controls-after-disconnect.txt" 2>&1

# Three frames the driver marks damaged (V4L2_BUF_FLAG_ERROR): broken, not dropped.
event "damaged frames"
for _ in 1 2 3; do ctl -c inject_v4l2_buf_flag_error=1; sleep 0.5; done

# The driver unbound and bound again: a new device with every control at its default.
event "unbind"
echo vivid.0 >/sys/bus/platform/drivers/vivid/unbind
sleep 2
echo vivid.0 >/sys/bus/platform/drivers/vivid/bind
event "bound"
sleep 14
event "after bind"
ctl --get-ctrl=gain,gain_automatic >"${out}/controls-after-bind.txt" 2>&1

wait "${node}"
echo "$?" >"${out}/node.rc"
event "node exited"
wait "${recorder}"
echo "$?" >"${out}/recorder.rc"

# A camera that is not there: refused at once, naming the cameras that are.
"${bin}/so101_camera_node" --camera top=/dev/video42 --duration 1 >"${out}/missing.log" 2>&1
echo "$?" >"${out}/missing.rc"
event "done"
