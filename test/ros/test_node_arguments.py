"""ROS arguments to a node executable: bad ones refused with the reason, exit status 2, no
traceback; an integer for a float parameter (``-p rate:=30``, ``rate: 30`` in a params file,
``ros2 param set`` later) taken as the DOUBLE it means."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from ros_test_tools import call, probe_node, running, wait_until

BIN = Path(sys.executable).parent


@pytest.mark.parametrize("executable", ["platform_simulator", "drive_interface"])
@pytest.mark.parametrize("case", ["missing", "malformed"])
def test_an_unusable_params_file_is_refused_by_name(
    tmp_path: Path, executable: str, case: str
) -> None:
    params = tmp_path / f"{case}.yaml"
    if case == "malformed":
        params.write_text("a: [1, 2\nb: {\n")
    result = subprocess.run(
        [str(BIN / executable), "--ros-args", "--params-file", str(params)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert "refusing to start: failed to initialize rcl: Couldn't parse params file" in output
    assert str(params) in output
    assert "Traceback" not in output


def _integer(name: str, value: int) -> ParameterMsg:
    """What ``ros2 param set /node name 30`` sends: an INTEGER."""
    return ParameterMsg(
        name=name, value=ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=value)
    )


def test_float_parameters_take_integers_from_p_a_params_file_and_param_set(
    tmp_path: Path,
) -> None:
    params = tmp_path / "drive.yaml"
    params.write_text(
        "/**/drive_interface:\n  ros__parameters:\n    publish_rate_hz: 30\n"
        "    plant:\n      damping_ns_per_m: 2\n"
    )
    ns = "/int_params"
    node = f"{ns}/drive_interface"
    command = [
        str(BIN / "drive_interface"),
        "--ros-args",
        "-r",
        f"__ns:={ns}",
        "--params-file",
        str(params),
        "-p",
        "max_frequency_hz:=250",
        "-p",
        "speed_model_enabled:=false",
    ]
    names = ["max_frequency_hz", "publish_rate_hz", "plant.damping_ns_per_m", "min_frequency_hz"]
    with running(command) as process, probe_node() as probe:

        def values() -> list[ParameterValue]:
            request = GetParameters.Request(names=names)
            return list(call(probe, GetParameters, f"{node}/get_parameters", request).values)

        assert wait_until(
            lambda: ("drive_interface", ns) in probe.get_node_names_and_namespaces(), 30.0
        ), process.poll()
        start = values()
        assert [v.type for v in start] == [ParameterType.PARAMETER_DOUBLE] * 4
        assert [v.double_value for v in start] == [250.0, 30.0, 2.0, 5.0]

        def set_parameter(parameter: ParameterMsg) -> object:
            request = SetParameters.Request(parameters=[parameter])
            return call(probe, SetParameters, f"{node}/set_parameters", request).results[0]

        result = set_parameter(_integer("min_frequency_hz", 10))
        assert result.successful, result.reason
        later = values()
        assert later[3].type == ParameterType.PARAMETER_DOUBLE
        assert later[3].double_value == 10.0

        # what `ros2 param set` answers out of range: the range as declared, never a made-up end
        below = set_parameter(_integer("plant.damping_ns_per_m", -1))
        assert not below.successful
        assert below.reason == "plant.damping_ns_per_m=-1.0 N*s/m must be >= 0 N*s/m"
        above = set_parameter(_integer("max_frequency_hz", 20000))
        assert not above.successful
        assert "Min: 0.1, Max: 10000.0" in above.reason
        assert values() == later


@pytest.mark.parametrize(
    ("executable", "argument", "reason"),
    [
        (
            "drive_interface",
            "plant.damping_ns_per_m:=-1",
            "plant.damping_ns_per_m=-1 N*s/m must be >= 0 N*s/m",
        ),
        ("drive_interface", "publish_rate_hz:=0", "publish_rate_hz=0 Hz must be >= 1 Hz"),
        (
            "platform_simulator",
            "drive_frequency_hz:=-20",
            "drive_frequency_hz=-20 Hz must be > 0 Hz",
        ),
    ],
)
def test_a_start_up_value_out_of_range_is_refused_with_the_range_as_declared(
    executable: str, argument: str, reason: str
) -> None:
    result = subprocess.run(
        [str(BIN / executable), "--ros-args", "-p", argument],
        capture_output=True,
        text=True,
        timeout=60,
    )
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert f"refusing to start: {reason}\n" in output
    assert "e+308" not in output
    assert "Traceback" not in output
