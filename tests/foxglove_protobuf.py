"""Foxglove's protobuf messages read by the protobuf wire format alone
(https://protobuf.dev/programming-guides/encoding/), field names taken from the schema's own
FileDescriptorSet (itself a protobuf message), independently of foxglove-sdk's encoder.

A message is a sequence of (field number << 3 | wire type, value): varint (0), 64-bit (1),
length-delimited (2: bytes, strings, sub-messages, packed numbers) and 32-bit (5).
"""

import struct

VARINT, FIXED64, DELIMITED, FIXED32 = 0, 1, 2, 5
# descriptor.proto's field numbers and types (FieldDescriptorProto.Type).
TYPE_DOUBLE, TYPE_FLOAT, TYPE_BOOL, TYPE_STRING, TYPE_MESSAGE = 1, 2, 8, 9, 11
TYPE_UINT32, TYPE_INT32, TYPE_FIXED32, TYPE_UINT64, TYPE_INT64 = 13, 5, 7, 4, 3


def varint(data: bytes, offset: int) -> tuple[int, int]:
    value, shift = 0, 0
    while True:
        byte = data[offset]
        offset += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if not byte & 0x80:
            return value, offset


def fields(data: bytes) -> list[tuple[int, int, object]]:
    """(field number, wire type, raw value) of every field, in order."""
    found, offset = [], 0
    while offset < len(data):
        key, offset = varint(data, offset)
        number, wire = key >> 3, key & 7
        if wire == VARINT:
            value, offset = varint(data, offset)
        elif wire == FIXED64:
            value, offset = data[offset : offset + 8], offset + 8
        elif wire == FIXED32:
            value, offset = data[offset : offset + 4], offset + 4
        elif wire == DELIMITED:
            length, offset = varint(data, offset)
            value, offset = data[offset : offset + length], offset + length
        else:
            raise AssertionError(f"wire type {wire} of field {number}")
        found.append((number, wire, value))
    return found


def descriptors(schema_data: bytes) -> dict[str, dict[int, tuple[str, int, str, bool]]]:
    """Every message type of a FileDescriptorSet: full name → {number: (name, type, type name, repeated)}."""
    types = {}
    for number, _, file in fields(schema_data):
        assert number == 1  # FileDescriptorSet.file
        file_fields = fields(file)
        package = next((v.decode() for n, _, v in file_fields if n == 2), "")
        for n, _, message in file_fields:
            if n == 4:  # FileDescriptorProto.message_type
                described = fields(message)
                name = next(v.decode() for k, _, v in described if k == 1)
                members = {}
                for k, _, field in described:
                    if k == 2:  # DescriptorProto.field
                        f = {fk: fv for fk, _, fv in fields(field)}
                        members[f[3]] = (f[1].decode(), f[5], f.get(6, b"").decode().lstrip("."), f.get(4) == 3)
                types[f"{package}.{name}"] = members
    return types


def decode(data: bytes, type_name: str, types: dict) -> dict:
    """The message as a dict by field name; repeated fields as lists."""
    members = types[type_name]
    message: dict = {name: [] for name, _, _, repeated in members.values() if repeated}
    for number, _, raw in fields(data):
        if number not in members:
            continue
        name, kind, sub, repeated = members[number]
        if kind == TYPE_DOUBLE:
            value = struct.unpack("<d", raw)[0]
        elif kind == TYPE_FLOAT:
            value = struct.unpack("<f", raw)[0]
        elif kind == TYPE_STRING:
            value = raw.decode()
        elif kind == TYPE_MESSAGE:
            value = decode(raw, sub, types)
        elif kind == TYPE_BOOL:
            value = bool(raw)
        elif kind == TYPE_FIXED32:
            value = struct.unpack("<I", raw)[0]
        else:
            value = raw
        if repeated:
            message[name].append(value)
        else:
            message[name] = value
    return message
