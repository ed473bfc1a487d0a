"""Sample messages of every mows_msgs type, with a non-default value in every field.

Built from the typestore's field definitions (no rclpy), as rosbags message objects; the
value of a field depends on its position so that two swapped fields do not compare equal.
"""

import numpy as np
from rosbags.typesys.store import Typestore

from mows.device.recording.bags import PARTS, REPOSITORY_PACKAGE, typestore


def interface_names(kind: str) -> list[str]:
    """Names of the interfaces of one kind (msg, srv, action) in the repository's mows_msgs."""
    return sorted(path.stem for path in (REPOSITORY_PACKAGE / kind).glob(f"*.{kind}"))


MESSAGES = interface_names("msg")
SERVICES = interface_names("srv")
ACTIONS = interface_names("action")

# Every type a bag may carry: messages, and the message parts of services and actions.
BAG_TYPES = [
    f"mows_msgs/{kind}/{name}{suffix}" for kind in PARTS for name in interface_names(kind) for suffix in PARTS[kind]
]

SEQUENCE_LENGTH = 3

# Non-default values per primitive type; the field position is added (or subtracted).
INTEGERS = {
    "uint8": 3,
    "int8": -3,
    "uint16": 300,
    "int16": -300,
    "uint32": 2**20,
    "int32": -(2**20),
    "uint64": 2**40,
    "int64": -(2**40),
}
FLOATS = ("float32", "float64")


def primitive(typename: str, position: int):
    """A non-default Python value of a primitive ROS type (exact in its type)."""
    if typename == "bool":
        return True  # False is the default
    if typename == "string":
        return f"s{position}·é"
    if typename in INTEGERS:
        base = INTEGERS[typename]
        return base + position if base > 0 else base - position
    if typename in FLOATS:
        return position + 0.375
    raise NotImplementedError(f"no sample value for the primitive type {typename}")


def primitive_array(typename: str, start: int, length: int):
    """``length`` sample values as rosbags holds an array: numpy for numbers, list for text."""
    if typename == "bool":  # both values, so that an element out of place shows
        return np.array([i % 2 == 0 for i in range(length)])
    values = [primitive(typename, start + i) for i in range(length)]
    if typename == "string":
        return values
    return np.array(values, dtype=np.dtype(typename))  # numpy knows the ROS names


def sample_message(msgtype: str, store: Typestore | None = None, offset: int = 0):
    """A rosbags message of ``msgtype`` whose every field holds a non-default value."""
    store = store or typestore()
    _constants, fields = store.fielddefs[msgtype]
    values = {}
    for position, (name, (nodetype, detail)) in enumerate(fields, start=offset + 1):
        values[name] = field_value(store, nodetype.name, detail, position)
    return store.types[msgtype](**values)


def field_value(store: Typestore, nodetype: str, detail, position: int):
    if nodetype == "BASE":
        return primitive(detail[0], position)
    if nodetype == "NAME":
        return sample_message(detail, store, position)
    (element_nodetype, element), length = detail
    length = length if nodetype == "ARRAY" else SEQUENCE_LENGTH
    if element_nodetype.name == "NAME":
        return [sample_message(element, store, position + i) for i in range(length)]
    return primitive_array(element[0], position, length)
