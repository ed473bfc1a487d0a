"""The channels Foxglove opens: each :class:`mows.viz.view.Shown` as a message of its topic's
schema, in bytes. The scene and the frames are Foxglove's own schemas (``foxglove.SceneUpdate``,
``foxglove.FrameTransforms``, protobuf, from ``foxglove-sdk``), which its 3D panel draws; the
plots are JSON with a JSON schema derived from their dataclass, so that the Plot panel offers
their fields by name. A live server (the ``mows_viz`` node) and an MCAP file
(:mod:`mows.viz.recording`) carry the same bytes.
"""

from __future__ import annotations

import dataclasses
import json
import math
import typing
from dataclasses import dataclass
from typing import Any

import numpy as np
from foxglove import messages as fm

from mows.records import stamps
from mows.records.json_numbers import finite_or_none
from mows.viz import view as v
from mows.viz.mount import FrameTransform
from mows.viz.scene import Arrow

HEAD_SHARE = 0.25  # of an arrow's length
SHAFT_DIAMETER_SHARE = 0.06  # of the largest arrow's length
COLOURS = {"B": (0.85, 0.2, 0.2), "B∥": (0.95, 0.6, 0.1), "G": (0.2, 0.45, 0.9), "pose": (0.5, 0.5, 0.5)}
# Each plot channel's dataclass (its JSON schema's name is mows.viz.<class name>).
PLOTS = {
    v.RAW: v.RawSample,
    v.RINGDOWN: v.RingdownPlot,
    v.SWEEP: v.SweepPlot,
    v.LAB: v.LabHistory,
    v.EXCITATION: v.ExcitationPlot,
    v.DIAGNOSTICS: v.DiagnosticsTable,
}
TOPICS = (v.SCENE, v.FRAMES, *PLOTS)


@dataclass(frozen=True)
class ChannelSchema:
    """What a channel is advertised with: its schema (name, encoding, bytes) and message encoding."""

    name: str
    encoding: str
    data: bytes
    message_encoding: str


def schema(topic: str) -> ChannelSchema:
    """The schema of one of :data:`TOPICS`."""
    if topic in (v.SCENE, v.FRAMES):
        found = (fm.SceneUpdate if topic == v.SCENE else fm.FrameTransforms).get_schema()
        return ChannelSchema(found.name, found.encoding, bytes(found.data), "protobuf")
    if topic not in PLOTS:
        raise ValueError(f"topic = {topic!r}: no such channel; the channels are {', '.join(TOPICS)}")
    cls = PLOTS[topic]
    return ChannelSchema(f"mows.viz.{cls.__name__}", "jsonschema", json.dumps(json_schema(cls)).encode(), "json")


def json_schema(cls: type) -> dict:
    """The JSON schema of a plot's dataclass: numbers, integers, strings, booleans and lists of
    them or of a dataclass; a number may be null (not finite)."""
    hints = typing.get_type_hints(cls)
    return {
        "type": "object",
        "title": cls.__name__,
        "properties": {f.name: _json_type(hints[f.name]) for f in dataclasses.fields(cls)},
    }


def _json_type(hint) -> dict:
    if typing.get_origin(hint) is list:
        (item,) = typing.get_args(hint)
        return {"type": "array", "items": _json_type(item)}
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        return json_schema(hint)
    kinds = {float: ["number", "null"], int: "integer", str: "string", bool: "boolean"}
    return {"type": kinds[hint]}


def payload(shown: v.Shown) -> bytes:
    """The bytes of ``shown`` on its topic's channel."""
    content: Any = shown.content
    if shown.topic == v.SCENE:
        return scene_update(content, shown.log_time_ns).encode()
    if shown.topic == v.FRAMES:
        return frame_transforms(content, shown.log_time_ns).encode()
    return json.dumps(finite_or_none(dataclasses.asdict(content)), ensure_ascii=False).encode()


def _timestamp(time_ns: int) -> fm.Timestamp:
    sec, nsec = divmod(int(time_ns), stamps.NS_PER_S)
    return fm.Timestamp(sec=sec, nsec=nsec)


def rotation_from_x(direction) -> np.ndarray:
    """The quaternion (x, y, z, w) turning +x onto the unit ``direction`` (Foxglove's arrows point along +x)."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    axis = np.cross([1.0, 0.0, 0.0], d)
    if np.linalg.norm(axis) < 1e-12:
        return np.array([0.0, 0.0, 0.0, 1.0]) if d[0] > 0 else np.array([0.0, 0.0, 1.0, 0.0])
    angle = math.acos(max(-1.0, min(1.0, d[0])))
    axis = axis / np.linalg.norm(axis)
    return np.append(axis * math.sin(angle / 2), math.cos(angle / 2))


def _pose(position_m, rotation) -> fm.Pose:
    x, y, z = (float(c) for c in position_m)
    qx, qy, qz, qw = (float(c) for c in rotation)
    return fm.Pose(position=fm.Vector3(x=x, y=y, z=z), orientation=fm.Quaternion(x=qx, y=qy, z=qz, w=qw))


def scene_update(entities: dict[str, list[Arrow]], time_ns: int) -> fm.SceneUpdate:
    """One scene entity per id (a probe's field arrows, a frame's axis arrow), each arrow with
    its label at its head."""
    longest = max((a.length_m for arrows in entities.values() for a in arrows), default=0.0) or 1.0
    shaft = SHAFT_DIAMETER_SHARE * longest
    scene = []
    for entity_id, arrows in entities.items():
        primitives, texts = [], []
        for arrow in arrows:
            r, g, b = COLOURS[arrow.kind]
            colour = fm.Color(r=r, g=g, b=b, a=1.0)
            primitives.append(
                fm.ArrowPrimitive(
                    pose=_pose(arrow.tail_m, rotation_from_x(arrow.direction)),
                    shaft_length=arrow.length_m * (1 - HEAD_SHARE),
                    shaft_diameter=shaft,
                    head_length=arrow.length_m * HEAD_SHARE,
                    head_diameter=2 * shaft,
                    color=colour,
                )
            )
            if arrow.label:
                head = np.asarray(arrow.tail_m) + np.asarray(arrow.direction) * arrow.length_m
                texts.append(
                    fm.TextPrimitive(
                        pose=_pose(head, (0.0, 0.0, 0.0, 1.0)),
                        billboard=True,
                        font_size=14.0,
                        scale_invariant=True,
                        color=colour,
                        text=arrow.label,
                    )
                )
        frame = arrows[0].frame_id if arrows else ""
        scene.append(
            fm.SceneEntity(
                timestamp=_timestamp(time_ns),
                frame_id=frame,
                id=entity_id,
                frame_locked=True,
                arrows=primitives,
                texts=texts,
            )
        )
    return fm.SceneUpdate(entities=scene)


def frame_transforms(frames: list[FrameTransform], time_ns: int) -> fm.FrameTransforms:
    return fm.FrameTransforms(
        transforms=[
            fm.FrameTransform(
                timestamp=_timestamp(time_ns),
                parent_frame_id=f.parent,
                child_frame_id=f.child,
                translation=fm.Vector3(
                    x=float(f.translation_m[0]), y=float(f.translation_m[1]), z=float(f.translation_m[2])
                ),
                rotation=fm.Quaternion(
                    x=float(f.rotation[0]), y=float(f.rotation[1]), z=float(f.rotation[2]), w=float(f.rotation[3])
                ),
            )
            for f in frames
        ]
    )
