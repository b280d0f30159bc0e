"""What `ros2 param` does, through rclpy's own parameter client (rclpy.parameter_client), for the
parameter tests of every node."""

from __future__ import annotations

from typing import Any

from harness import wait_until
from rcl_interfaces.msg import ParameterType, ParameterValue
from rclpy.parameter import Parameter, parameter_value_to_python

SERVICE_TIMEOUT = 20.0
CALL_TIMEOUT = 10.0


class ParameterPeer:
    """rclpy's AsyncParameterClient for one remote node, with blocking calls."""

    def __init__(self, probe, node_name: str, process=None):
        from rclpy.parameter_client import AsyncParameterClient

        self.process = process
        self.client = AsyncParameterClient(probe.node, node_name)
        wait_until(
            lambda: self.client.services_are_ready(),
            SERVICE_TIMEOUT,
            f"the parameter services of {node_name}",
            process,
        )

    def _result(self, future):
        wait_until(future.done, CALL_TIMEOUT, "a parameter service answer", self.process)
        if future.exception() is not None:
            raise future.exception()
        return future.result()

    def names(self) -> list[str]:
        return list(self._result(self.client.list_parameters()).result.names)

    def list(self, prefixes: list[str] | None = None, depth: int = 0):
        """ListParameters' result (names and prefixes) for `prefixes` and `depth` (0: any)."""
        return self._result(self.client.list_parameters(prefixes=prefixes, depth=depth)).result

    def get(self, *names: str) -> list[Any]:
        values = self._result(self.client.get_parameters(list(names))).values
        return [parameter_value_to_python(value) for value in values]

    def types(self, *names: str) -> list[int]:
        return list(self._result(self.client.get_parameter_types(list(names))).types)

    def describe(self, *names: str):
        return list(self._result(self.client.describe_parameters(list(names))).descriptors)

    def set(self, **values: Any):
        """Sets each parameter on its own; returns the SetParametersResult of each."""
        parameters = [Parameter(name, value=value) for name, value in values.items()]
        return list(self._result(self.client.set_parameters(parameters)).results)

    def set_raw(self, name: str, value: ParameterValue):
        """Sets one parameter to a raw ParameterValue (a type rclpy's Parameter would not build)."""
        from rcl_interfaces.msg import Parameter as ParameterMsg
        from rcl_interfaces.srv import SetParameters

        request = SetParameters.Request(parameters=[ParameterMsg(name=name, value=value)])
        return list(self._result(self.client._set_parameter_client.call_async(request)).results)

    def set_atomically(self, **values: Any):
        parameters = [Parameter(name, value=value) for name, value in values.items()]
        return self._result(self.client.set_parameters_atomically(parameters)).result


def not_set() -> ParameterValue:
    return ParameterValue(type=ParameterType.PARAMETER_NOT_SET)


def documented(node: str) -> dict[str, bool]:
    """docs/parameters.md's table of `node`: parameter name -> dynamic."""
    from harness import REPO_ROOT

    text = (REPO_ROOT / "docs" / "parameters.md").read_text()
    section = text.split(f"\n## {node}", 1)[1].split("\n## ", 1)[0]
    rows = [line.split("|") for line in section.splitlines() if line.startswith("| `")]
    return {row[1].strip().strip("`"): "dynamic" in row[3] for row in rows}


def assert_documented(peer: ParameterPeer, node: str) -> None:
    """The node's parameters are exactly the documented ones, dynamic where documented so."""
    names = sorted(peer.names())
    served = {d.name: not d.read_only for d in peer.describe(*names)}
    assert served == documented(node), f"{node}: docs/parameters.md differs from what the node serves"
