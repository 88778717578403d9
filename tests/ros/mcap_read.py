"""Reads an MCAP recording as a user's tools would and prints one JSON object on stdout.

- The file is opened with the `mcap` package (PyPI) through its summary (the index that
  `ros2 bag info` and Foxglove read) and read message by message.
- Every message is decoded twice: with `mcap-ros2-support` from the schema the file carries
  (what Foxglove does without ROS), and with rclpy's own type support for the ROS type the
  schema names. The two must give the same values, field for field.
- Each schema's first definition is compared with the interface definition installed with the
  ROS message packages (`share/<package>/msg/<Name>.msg`): same fields, types and constants.

Usage: python mcap_read.py FILE.mcap
"""

import importlib
import json
import math
import os
import re
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.serialization import deserialize_message

PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
              "int32", "uint32", "int64", "uint64", "string", "wstring"}


def fields_of(text, package):
    """(type, name) of each field and constant of a definition, types qualified, defaults and
    comments dropped."""
    out = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        ty, rest = line.split(None, 1)
        base, _, array = ty.partition("[")
        array = "[" + array if array else ""
        if base == "Header":
            base = "std_msgs/Header"
        elif base not in PRIMITIVES and "/" not in base:
            base = f"{package}/{base}"
        if "=" in rest:
            name, value = (s.strip() for s in rest.split("=", 1))
            out.append((base + array, name, value))
        else:
            out.append((base + array, rest.split()[0]))
    return out


def installed_definition(schema_name):
    package, _, name = schema_name.split("/")
    path = os.path.join(sys.prefix, "share", package, "msg", f"{name}.msg")
    with open(path) as f:
        return f.read()


def same(a, b, path=""):
    """The first difference between an rclpy message and a decoded one, or None."""
    if hasattr(a, "get_fields_and_field_types"):
        for field in a.get_fields_and_field_types():
            diff = same(getattr(a, field), getattr(b, field), f"{path}.{field}")
            if diff:
                return diff
        return None
    if isinstance(a, (list, tuple)) or hasattr(a, "tolist"):
        a = list(a.tolist() if hasattr(a, "tolist") else a)
        b = list(b.tolist() if hasattr(b, "tolist") else b)
        if len(a) != len(b):
            return f"{path}: {len(a)} against {len(b)} elements"
        for i, (x, y) in enumerate(zip(a, b)):
            diff = same(x, y, f"{path}[{i}]")
            if diff:
                return diff
        return None
    if isinstance(a, float) and math.isnan(a) and isinstance(b, float) and math.isnan(b):
        return None
    if isinstance(a, bytes) and len(a) == 1 and isinstance(b, int):
        a = a[0]
    return None if a == b else f"{path}: {a!r} against {b!r}"


def ros_class(schema_name):
    """The rclpy message class, or None when its package is not installed (tf2_msgs is not on
    PyPI)."""
    package, kind, name = schema_name.split("/")
    try:
        return getattr(importlib.import_module(f"{package}.{kind}"), name)
    except ModuleNotFoundError:
        return None


def main():
    path = sys.argv[1]
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        summary = reader.get_summary()
        channels = {}
        for cid, ch in summary.channels.items():
            schema = summary.schemas[ch.schema_id]
            first = schema.data.decode().split("\n" + "=" * 80 + "\n")[0]
            package = schema.name.split("/")[0]
            try:
                expected = fields_of(installed_definition(schema.name), package)
                definition_matches = fields_of(first, package) == expected
            except FileNotFoundError:
                definition_matches = None
            channels[ch.topic] = {
                "type": schema.name,
                "schema_encoding": schema.encoding,
                "message_encoding": ch.message_encoding,
                "summary_count": summary.statistics.channel_message_counts.get(cid, 0),
                "count": 0,
                "definition_matches": definition_matches,
                "checked_natively": ros_class(schema.name) is not None,
                "mismatches": [],
                "frames": [],
                "stamps_ns": [],
            }
        last_log_time = 0
        log_time_order = True
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            c = channels[channel.topic]
            c["count"] += 1
            log_time_order &= message.log_time >= last_log_time
            last_log_time = message.log_time
            cls = ros_class(schema.name)
            if cls is not None:
                diff = same(deserialize_message(message.data, cls), decoded)
                if diff and len(c["mismatches"]) < 3:
                    c["mismatches"].append(diff)
            if hasattr(decoded, "header"):
                c["stamps_ns"].append(decoded.header.stamp.sec * 10**9 + decoded.header.stamp.nanosec)
            for t in getattr(decoded, "transforms", []):
                if t.child_frame_id not in c["frames"]:
                    c["frames"].append(t.child_frame_id)
    print(json.dumps({
        "profile": header.profile,
        "library": header.library,
        "message_count": summary.statistics.message_count,
        "log_time_in_order": log_time_order,
        "channels": channels,
    }))


if __name__ == "__main__":
    main()
