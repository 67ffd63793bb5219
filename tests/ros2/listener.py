"""A ROS 2 subscriber for netfi's tests: writes one CSV row per message
received on TOPIC (`index,source_ns,received_ns,sequence`: the index the
talker put in the message, and the DDS message info's source and reception
timestamps), until COUNT have come, or none for --idle-s after the first,
or --timeout-s in all.

usage: listener.py TOPIC OUT_CSV [--type string|pose|transform|joint] [--qos reliable|best_effort] [--count N]
                   [--idle-s S] [--timeout-s S] [--ready FILE] [--name NODE]
"""
import argparse
import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor

from talker import TYPES, msg_type, node_and_qos


def index_of(kind, m):
    return int(m.data.split(" ")[0]) if kind == "string" else int(m.header.frame_id)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("topic")
    p.add_argument("out")
    p.add_argument("--type", default="string", choices=TYPES)
    p.add_argument("--qos", default="reliable", choices=["reliable", "best_effort"])
    p.add_argument("--depth", type=int, default=1000)
    p.add_argument("--count", type=int, default=0)
    p.add_argument("--idle-s", type=float, default=3.0)
    p.add_argument("--timeout-s", type=float, default=120.0)
    p.add_argument("--ready", help="a file written once subscribed")
    p.add_argument("--name", default="listener")
    a = p.parse_args()

    node, qos = node_and_qos(a, a.depth)
    rows = []

    def got(m, info):
        rows.append((index_of(a.type, m), info["source_timestamp"], info["received_timestamp"], info.get("publication_sequence_number") or 0))

    node.create_subscription(msg_type(a.type), a.topic, got, qos)
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    if a.ready:
        open(a.ready, "w").close()
    t0 = time.monotonic()
    last = None
    while True:
        n = len(rows)
        ex.spin_once(timeout_sec=0.05)
        now = time.monotonic()
        if len(rows) != n:
            last = now
        if a.count and len(rows) >= a.count:
            break
        if last is not None and now - last > a.idle_s:
            break
        if now - t0 > a.timeout_s:
            break
    with open(a.out, "w") as f:
        f.write("index,source_ns,received_ns,sequence\n")
        for r in rows:
            f.write(",".join(str(x) for x in r) + "\n")
    print(f"listener: {len(rows)} received on {a.topic}", file=sys.stderr, flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
