"""Message definitions parsed through ROS's own parser (feeder_ros.bag.msgdef): the fields the
CDR decoder walks, checked against rclpy's generated classes; schemas split into their types;
refusals name the type and the reason without printing anything."""

from __future__ import annotations

import pytest

from feeder_ros.bag.errors import MessageDefinitionError
from feeder_ros.bag.msgdef import Field, parse_msg_text, parse_ros2msg_schema
from feeder_ros.bag.schemas import ros2msg_schema
from feeder_ros.recording import message_class

TEXT = """\
# a comment line
std_msgs/Header header   # trailing comment
uint8 MODE_A = 1
string NAME = "a # not a comment"
float64[] samples
int32[3] triple
string<=5 short_text
string[<=3] words
byte raw
PartState[<=4] parts     # relative: this package's type
"""

# rclpy's names of our primitive types
RCLPY = {"float64": "double", "float32": "float", "bool": "boolean", "byte": "octet",
         "char": "uint8"}  # fmt: skip


def test_fields_constants_comments_arrays_and_relative_types() -> None:
    assert parse_msg_text("feeder_ros/msg/Example", TEXT) == (
        Field("header", "std_msgs/msg/Header"),
        Field("samples", "float64", "seq"),
        Field("triple", "int32", "fixed", 3),
        Field("short_text", "string"),
        Field("words", "string", "seq"),
        Field("raw", "byte"),
        Field("parts", "feeder_ros/msg/PartState", "seq"),
    )


def rclpy_kind(field: Field) -> str:
    base = RCLPY.get(field.type, field.type)
    if "/" in base:
        base = base.replace("/msg/", "/")
    if field.array == "fixed":
        return f"{base}[{field.count}]"
    return f"sequence<{base}>" if field.array == "seq" else base


@pytest.mark.parametrize(
    "type_name",
    [
        "sensor_msgs/msg/Imu",
        "diagnostic_msgs/msg/DiagnosticArray",
        "feeder_ros/msg/VehicleEstimate",
        "feeder_ros/msg/PartStateArray",
        "feeder_ros/msg/AccelerometerBatch",
        "feeder_ros/msg/DriveState",
    ],
)
def test_every_type_of_a_schema_matches_rclpy_s_generated_class(type_name: str) -> None:
    definitions = parse_ros2msg_schema(type_name, ros2msg_schema(type_name))
    assert type_name in definitions
    for name, fields in definitions.items():
        expected = message_class(name).get_fields_and_field_types()
        # rclpy spells bounded strings string<=N; the decoder reads them as strings
        expected = {k: v.split("<=")[0] if v.startswith("string<=") else v
                    for k, v in expected.items()}  # fmt: skip
        assert {f.name: rclpy_kind(f) for f in fields} == expected, name


def test_an_action_feedback_type_name_is_accepted() -> None:
    fields = parse_msg_text(
        "feeder_ros/action/FeedParts_FeedbackMessage",
        "unique_identifier_msgs/UUID goal_id\nFeedParts_Feedback feedback\n",
    )
    assert fields == (
        Field("goal_id", "unique_identifier_msgs/msg/UUID"),
        Field("feedback", "feeder_ros/msg/FeedParts_Feedback"),
    )


def test_a_bad_line_is_refused_with_the_type_and_reason_and_nothing_printed(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(MessageDefinitionError) as refused:
        parse_msg_text("pkg/msg/Broken", "float64 x\nflo@t y\n")
    assert refused.value.type_name == "pkg/msg/Broken"
    assert "'flo@t' is an invalid message name" in refused.value.reason
    assert capsys.readouterr() == ("", "")


def test_a_schema_that_lacks_a_type_or_contains_itself_is_refused() -> None:
    with pytest.raises(MessageDefinitionError, match="lacks the definition of pkg/msg/Inner"):
        parse_ros2msg_schema("pkg/msg/Outer", "Inner inner\n")
    loop = "pkg/Outer next\n" + "=" * 80 + "\nMSG: pkg/Outer\npkg/Outer next\n"
    with pytest.raises(MessageDefinitionError, match="recursive"):
        parse_ros2msg_schema("pkg/msg/Outer", loop)
