"""rosbags sample messages as rclpy messages: the class of a rosbag2 type name, and a copy
field by field (needs the built workspace: install/setup.bash)."""

import importlib

import numpy as np
from rosidl_parser.definition import AbstractNestedType, NamespacedType


def rclpy_class(msgtype: str) -> type:
    """The rclpy class of a rosbag2 type name: mows_msgs/srv/RunCycle_Request is
    mows_msgs.srv.RunCycle.Request."""
    package, kind, name = msgtype.split("/")
    interface, _, part = name.partition("_")
    cls = getattr(importlib.import_module(f"{package}.{kind}"), interface)
    return getattr(cls, part) if part else cls


def class_of(namespaced: NamespacedType) -> type:
    return getattr(importlib.import_module(".".join(namespaced.namespaces)), namespaced.name)


def to_rclpy(message, cls: type):
    """A ``cls`` instance holding the values of the rosbags ``message``."""
    result = cls()
    for name, slot in zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES):
        setattr(result, name, convert(getattr(message, name), slot))
    return result


def convert(value, slot):
    if isinstance(slot, NamespacedType):
        return to_rclpy(value, class_of(slot))
    if isinstance(slot, AbstractNestedType) and isinstance(slot.value_type, NamespacedType):
        return [to_rclpy(element, class_of(slot.value_type)) for element in value]
    # rclpy takes lists (not numpy arrays) for sequences; tolist gives Python numbers.
    return value.tolist() if isinstance(value, np.ndarray) else value
