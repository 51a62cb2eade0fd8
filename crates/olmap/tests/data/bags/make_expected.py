"""Expected values for olmap's ROS 2 bag tests, written by independent readers: the Python
`mcap` package (container: topics, counts, log times) and `rosbags` 0.11.9 (CDR decoding
with its own ROS 2 Humble type store; test_msgs types are registered from the bag's own
schema text). Reads the bags under $OLMAP_DATA/ros2_bags (default ../shared/data) and
writes expected.json beside this script.

Run: python3 -m venv v && v/bin/pip install rosbags==0.11.9 mcap numpy && v/bin/python make_expected.py"""
import dataclasses, glob, json, math, os, sys
import numpy as np
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.environ.get("OLMAP_DATA") or os.path.join(HERE, "..", "..", "..", "..", "..", "..", "shared", "data")
BAGS = os.path.join(DATA, "ros2_bags")


def plain(v):
    if isinstance(v, np.ndarray):
        return [plain(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    if isinstance(v, float):
        return v if math.isfinite(v) else ("nan" if math.isnan(v) else ("inf" if v > 0 else "-inf"))
    if isinstance(v, (bool, int, str)):
        return v
    if hasattr(v, "__dataclass_fields__"):
        return {f.name: plain(getattr(v, f.name)) for f in dataclasses.fields(v) if f.name != "__msgtype__"}
    if isinstance(v, (np.floating,)):
        return plain(float(v))
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.bool_,)):
        return bool(v)
    raise TypeError(type(v))


def register(ts, schema_name, text):
    # The schema text: root definition, then "MSG: pkg/Type" sections.
    parts = text.split("=" * 80)
    types = {}
    types.update(get_types_from_msg(parts[0], schema_name))
    for p in parts[1:]:
        lines = p.strip().splitlines()
        name = lines[0].split(":", 1)[1].strip()
        if "/msg/" not in name:
            pkg, ty = name.split("/")
            name = f"{pkg}/msg/{ty}"
        types.update(get_types_from_msg("\n".join(lines[1:]), name))
    ts.register(types)


out = {}
for bag in sorted(os.listdir(BAGS)):
    files = sorted(glob.glob(os.path.join(BAGS, bag, "*.mcap")), key=lambda f: int("".join(c for c in os.path.basename(f) if c.isdigit()) or 0))
    if not files:
        continue
    ts = get_typestore(Stores.ROS2_HUMBLE)
    topics, decoded = {}, {}
    for f in files:
        with open(f, "rb") as fh:
            for sch, ch, m in make_reader(fh).iter_messages(log_time_order=False):
                t = topics.setdefault(ch.topic, {"name": ch.topic, "type": sch.name, "count": 0, "first_log_time_ns": m.log_time, "last_log_time_ns": m.log_time})
                t["count"] += 1
                t["first_log_time_ns"] = min(t["first_log_time_ns"], m.log_time)
                t["last_log_time_ns"] = max(t["last_log_time_ns"], m.log_time)
                if bag == "cdr_test" or (bag in ("talker", "wbag") and sch.name == "std_msgs/msg/String"):
                    if sch.name not in ts.types:
                        register(ts, sch.name, sch.data.decode())
                    decoded.setdefault(ch.topic, []).append(plain(ts.deserialize_cdr(m.data, sch.name)))
    entry = {"topics": sorted(topics.values(), key=lambda t: t["name"])}
    if bag == "cdr_test":
        entry["messages"] = decoded
    elif decoded:
        entry["first_and_last"] = {k: [v[0], v[-1]] for k, v in decoded.items()}
    out[bag] = entry
with open(os.path.join(HERE, "expected.json"), "w") as fh:
    json.dump(out, fh, indent=1, sort_keys=True)
    fh.write("\n")
print("ok", {k: len(v["topics"]) for k, v in out.items()})
