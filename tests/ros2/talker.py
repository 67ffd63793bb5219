"""A ROS 2 publisher for netfi's tests: COUNT messages on TOPIC at RATE,
each carrying its index (std_msgs/String: `data`; the other types: the
header's `frame_id`), then it stays a while so that a reliable subscriber
gets every message, and leaves cleanly (or, with --hang, stays until
killed).

Types: `string` (std_msgs/String), `pose` (geometry_msgs/PoseStamped, the
index as the x of the position), `transform` (geometry_msgs/TransformStamped
on a plain topic, a translation that winds along a helix) and `joint`
(sensor_msgs/JointState, six joints that swing). With --sent, each message's
index and coordinates (a pose's position and orientation, a joint state's
positions), exactly as sent, go to a CSV.

usage: talker.py TOPIC COUNT [--rate-hz R] [--type string|pose|transform|joint]
                 [--qos reliable|best_effort] [--wait-subs N] [--linger-s S] [--hang]
                 [--name NODE] [--ready FILE] [--first I] [--big-every K --big-bytes N]
                 [--sent CSV]
"""
import math
import argparse
import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy


JOINTS = 6


def coordinates(kind, i):
    """What message `i` of `kind` says of where the arm is."""
    if kind == "pose":
        return [float(i), 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    if kind == "transform":
        a = i / 50.0
        return [0.1 * math.cos(a), 0.1 * math.sin(a), 0.001 * i, 0.0, 0.0, math.sin(a / 2), math.cos(a / 2)]
    return [0.5 * math.sin(i / 40.0 + j) + 0.002 * i * (j - 2) for j in range(JOINTS)]


def message(kind, i, pad=0):
    m = msg_type(kind)()
    if kind == "string":
        # The index, then `pad` spaces (a larger message, same index).
        m.data = str(i) + " " * pad
        return m
    m.header.frame_id = str(i)
    q = coordinates(kind, i)
    if kind == "pose":
        p, o = m.pose.position, m.pose.orientation
        p.x, p.y, p.z, o.x, o.y, o.z, o.w = q
    elif kind == "transform":
        m.child_frame_id = "tool"
        p, o = m.transform.translation, m.transform.rotation
        p.x, p.y, p.z, o.x, o.y, o.z, o.w = q
    else:
        m.name = [f"joint_{j}" for j in range(JOINTS)]
        m.position = q
    return m


def msg_type(kind):
    if kind == "string":
        from std_msgs.msg import String
        return String
    if kind == "pose":
        from geometry_msgs.msg import PoseStamped
        return PoseStamped
    if kind == "transform":
        from geometry_msgs.msg import TransformStamped
        return TransformStamped
    from sensor_msgs.msg import JointState
    return JointState


TYPES = ["string", "pose", "transform", "joint"]


def node_and_qos(a, depth):
    """rclpy started; the node named --name, and the --qos profile keeping
    the last `depth` messages."""
    rclpy.init()
    node = rclpy.create_node(a.name)
    rel = ReliabilityPolicy.RELIABLE if a.qos == "reliable" else ReliabilityPolicy.BEST_EFFORT
    return node, QoSProfile(depth=depth, reliability=rel, history=HistoryPolicy.KEEP_LAST)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("topic")
    p.add_argument("count", type=int)
    p.add_argument("--rate-hz", type=float, default=200.0)
    p.add_argument("--type", default="string", choices=TYPES)
    p.add_argument("--qos", default="reliable", choices=["reliable", "best_effort"])
    p.add_argument("--depth", type=int, default=None, help="history depth (default: COUNT, so that a reliable writer keeps every message until it is acknowledged, however late the reader is)")
    p.add_argument("--wait-subs", type=int, default=1, help="subscribers to wait for before publishing")
    p.add_argument("--wait-s", type=float, default=30.0)
    p.add_argument("--linger-s", type=float, default=2.0)
    p.add_argument("--hang", action="store_true", help="after the last message, stay until killed")
    p.add_argument("--name", default="talker")
    p.add_argument("--first", type=int, default=0, help="the first message's index")
    p.add_argument("--big-every", type=int, default=0, help="every K-th message is --big-bytes larger")
    p.add_argument("--big-bytes", type=int, default=0)
    p.add_argument("--ready", help="a file written once the subscribers are there")
    p.add_argument("--sent", help="a CSV of each message's index and coordinates, as sent")
    a = p.parse_args()

    node, qos = node_and_qos(a, a.depth or max(a.count, 1))
    pub = node.create_publisher(msg_type(a.type), a.topic, qos)
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    t0 = time.monotonic()
    while pub.get_subscription_count() < a.wait_subs:
        if time.monotonic() - t0 > a.wait_s:
            print(f"talker: no subscriber on {a.topic} within {a.wait_s} s", file=sys.stderr)
            return 2
        ex.spin_once(timeout_sec=0.02)
    if a.ready:
        open(a.ready, "w").close()
    period = 1.0 / a.rate_hz
    start = time.monotonic()
    sent = []
    for i in range(a.count):
        due = start + i * period
        while True:
            left = due - time.monotonic()
            if left <= 0:
                break
            time.sleep(min(left, 0.01))
        big = a.big_every and (i + 1) % a.big_every == 0
        pub.publish(message(a.type, a.first + i, a.big_bytes if big else 0))
        if a.sent and a.type != "string":
            sent.append([a.first + i] + coordinates(a.type, a.first + i))
    if a.sent:
        with open(a.sent, "w") as f:
            f.write("index," + ",".join(f"q{k}" for k in range(len(sent[0]) - 1 if sent else 0)) + "\n")
            for r in sent:
                # repr: each float exactly as sent.
                f.write(",".join(repr(x) for x in r) + "\n")
    print(f"talker: {a.count} sent on {a.topic}", file=sys.stderr, flush=True)
    end = time.monotonic() + a.linger_s
    while a.hang or time.monotonic() < end:
        ex.spin_once(timeout_sec=0.05)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
