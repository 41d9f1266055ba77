"""ROS 2 message types on the wire without a ROS installation: Cyclone DDS IDL structs generated
from rosbags' ROS 2 type store, the one schema of `graphloc import` (`idl_type`), and received
samples adapted to what the bag import's converter reads (`as_message`), so bags and live
topics share one converter."""

from __future__ import annotations

import dataclasses
import functools
import types

import numpy as np

# rosbags base type -> the IDL annotation (cyclonedds.idl.types); byte / uint8 sequences are
# `bytes` (CDR sequence<octet>: the same bytes on the wire, decoded without a Python list)
_BASE = {
    "bool": bool,
    "byte": "uint8",
    "char": "uint8",
    "int8": "int8",
    "uint8": "uint8",
    "int16": "int16",
    "uint16": "uint16",
    "int32": "int32",
    "uint32": "uint32",
    "int64": "int64",
    "uint64": "uint64",
    "float32": "float32",
    "float64": "float64",
    "string": str,
}


# graphloc's own message: one line of a log table (docs/log_format.md), for sources whose rows
# have no ROS message (graphloc.live.ros2.Ros2LogSource); stamp: the row's time
GRAPHLOC_MSGS = {
    "graphloc_msgs/msg/LogRow": "std_msgs/Header header\nstring robot\nstring table\nstring line\n"
}


@functools.cache
def typestore():
    """rosbags' ROS 2 Humble type store with vision_msgs 4 (the types of docs/rosbag.md) and
    graphloc_msgs (GRAPHLOC_MSGS)."""
    from rosbags.typesys import get_types_from_msg

    from graphloc.datasets.rosbag import typestore as writing_typestore

    ts = writing_typestore("ros2")
    for name, text in GRAPHLOC_MSGS.items():
        ts.register(get_types_from_msg(text, name))
    return ts


def dds_topic(topic: str) -> str:
    """ROS 2 topic name -> its DDS topic name (rmw's `rt/` prefix)."""
    return "rt/" + topic.lstrip("/")


def dds_type_name(msgtype: str) -> str:
    """`pkg/msg/Type` -> `pkg::msg::dds_::Type_` (rosidl's DDS type name)."""
    pkg, kind, name = msgtype.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def _base(name: str):
    from cyclonedds.idl import types as t

    a = _BASE[name]
    return getattr(t, a) if isinstance(a, str) else a


def _annotation(node):
    from cyclonedds.idl import types as t

    kind, spec = node
    kind = int(kind)  # rosbags Nodetype: BASE 1, NAME 2, ARRAY 3, SEQUENCE 4
    if kind == 1:
        return _base(spec[0])
    if kind == 2:
        return idl_type(spec)
    inner, size = spec
    if kind == 4 and int(inner[0]) == 1 and inner[1][0] in ("uint8", "byte", "char"):
        return bytes
    sub = _annotation(inner)
    return t.array[sub, size] if kind == 3 else t.sequence[sub]


@functools.cache
def idl_type(msgtype: str) -> type:
    """The Cyclone DDS struct of ROS 2 type `msgtype` (e.g. "nav_msgs/msg/Odometry");
    KeyError for a type the schema does not hold."""
    from cyclonedds.idl import IdlStruct

    fields = typestore().fielddefs[msgtype][1]
    ann = {name: _annotation(node) for name, node in fields}
    name = msgtype.rsplit("/", 1)[1] + "_"
    cls = types.new_class(
        name,
        (IdlStruct,),
        {"typename": dds_type_name(msgtype)},
        lambda ns: ns.update({"__annotations__": ann, "__module__": __name__}),
    )
    return dataclasses.dataclass(cls)


# the message types whose byte buffer the converters read as an array (images, clouds)
_BUFFERS = ("sensor_msgs/msg/Image", "sensor_msgs/msg/PointCloud2")


def as_message(msgtype: str, sample):
    """A received DDS sample as the message `graphloc.datasets.rosbag_messages` converts: the
    same attributes as rosbags' message, `data` of images and clouds a uint8 array."""
    if msgtype in _BUFFERS:
        return dataclasses.replace(sample, data=np.frombuffer(sample.data, dtype=np.uint8))
    return sample
