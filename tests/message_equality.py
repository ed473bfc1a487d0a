"""Field-by-field comparison of two messages, rclpy or rosbags alike: numbers, strings and
nested messages must be equal, numeric arrays equal element by element (exactly)."""

import array
import dataclasses

import numpy as np


def field_names(message) -> list[str] | None:
    """The field names of a ROS message object (rclpy or rosbags), None for other values."""
    if hasattr(message, "get_fields_and_field_types"):
        return list(message.get_fields_and_field_types())
    if dataclasses.is_dataclass(message):  # rosbags; its __msgtype__ is a field too
        return [f.name for f in dataclasses.fields(message) if not f.name.startswith("__")]
    return None


def assert_same(actual, expected, path: str = "message") -> None:
    names = field_names(expected)
    if names is not None:
        assert field_names(actual) == names, f"{path}: fields differ"
        for name in names:
            assert_same(getattr(actual, name), getattr(expected, name), f"{path}.{name}")
    elif isinstance(expected, (np.ndarray, array.array)):
        same = np.array_equal(np.asarray(actual), np.asarray(expected))
        assert same, f"{path}: {actual} != {expected}"
    elif isinstance(expected, list):
        assert len(actual) == len(expected), f"{path}: {len(actual)} elements, not {len(expected)}"
        for index, (a, e) in enumerate(zip(actual, expected)):
            assert_same(a, e, f"{path}[{index}]")
    else:
        assert actual == expected, f"{path}: {actual!r} != {expected!r}"
