"""Is this process inside a private network namespace with only loopback? The stack's rule: every
DDS participant opened here (a node, an rclpy tool, a test) lives in one, so discovery multicast
never leaves the machine (scripts/isolated makes one)."""

from __future__ import annotations

import fcntl
import socket
import struct

_SIOCGIFFLAGS = 0x8913
_IFF_UP = 0x1
_IFF_MULTICAST = 0x1000


def network_namespace_problem() -> str | None:
    """Why DDS must not be used from this process, or None when it is inside a private network
    namespace with only loopback, lo up, multicast-capable, and multicast routed on lo.

    Everything is read from the process's own network namespace (/proc/self/net, an ioctl on a
    socket); /sys/class/net would show the host's interfaces even inside a namespace.
    """
    try:
        with open("/proc/self/net/dev", encoding="ascii") as f:
            ifaces = sorted(line.split(":", 1)[0].strip() for line in f.readlines()[2:] if ":" in line)
    except OSError as error:
        return f"cannot read /proc/self/net/dev ({error})"
    if ifaces != ["lo"]:
        return f"this process sees the network interfaces {ifaces}, not only 'lo': it is not inside a private network namespace"
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            raw = fcntl.ioctl(s.fileno(), _SIOCGIFFLAGS, struct.pack("16sh", b"lo", 0))
        flags = struct.unpack("16sh", raw[:18])[1]
    except OSError as error:
        return f"cannot read the flags of lo ({error})"
    if not flags & _IFF_UP:
        return "lo is down in this namespace (ip link set lo up)"
    if not flags & _IFF_MULTICAST:
        return "lo has multicast off (ip link set lo multicast on)"
    try:
        with open("/proc/self/net/route", encoding="ascii") as f:
            routes = [line.split() for line in f.readlines()[1:]]
    except OSError as error:
        return f"cannot read /proc/self/net/route ({error})"
    # 224.0.0.0/4 in the little-endian hex of /proc/net/route.
    if not any(r[0] == "lo" and r[1] == "000000E0" and r[7] == "000000F0" for r in routes if len(r) >= 8):
        return "no multicast route on lo (ip route add 224.0.0.0/4 dev lo): DDS discovery would fail"
    return None


def isolated_command(command: list[str]) -> list[str]:
    """`command` as it must run to open DDS participants: as it is inside a private network
    namespace, else behind scripts/isolated (which makes one for it)."""
    if network_namespace_problem() is None:
        return command
    from ..paths import isolated_wrapper

    return [str(isolated_wrapper()), *command]
