"""A plain rclpy relay node, as a ROS lab writes one: it subscribes to IN
and republishes each message on OUT from its callback, the same QoS on
both sides (reliable unless --qos says otherwise, keeping the last
--depth). It subscribes only once OUT has --wait-subs subscribers, then
writes --ready; it runs until none came for --idle-s after the first, or
--timeout-s in all, and says how many it relayed.

usage: relay_node.py IN OUT [--type string|pose|transform|joint] [--qos reliable|best_effort]
                     [--depth N] [--wait-subs N] [--idle-s S] [--timeout-s S] [--ready FILE] [--name NODE]
"""
import argparse
import sys
import time

from rclpy.executors import SingleThreadedExecutor

from talker import TYPES, msg_type, node_and_qos


def main():
    p = argparse.ArgumentParser()
    p.add_argument("topic_in")
    p.add_argument("topic_out")
    p.add_argument("--type", default="string", choices=TYPES)
    p.add_argument("--qos", default="reliable", choices=["reliable", "best_effort"])
    p.add_argument("--depth", type=int, default=1000)
    p.add_argument("--wait-subs", type=int, default=1)
    p.add_argument("--wait-s", type=float, default=30.0)
    p.add_argument("--idle-s", type=float, default=5.0)
    p.add_argument("--timeout-s", type=float, default=600.0)
    p.add_argument("--ready", help="a file written once subscribed")
    p.add_argument("--name", default="relay")
    a = p.parse_args()

    import rclpy

    node, qos = node_and_qos(a, a.depth)
    pub = node.create_publisher(msg_type(a.type), a.topic_out, qos)
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    t0 = time.monotonic()
    while pub.get_subscription_count() < a.wait_subs:
        if time.monotonic() - t0 > a.wait_s:
            print(f"relay: no subscriber on {a.topic_out} within {a.wait_s} s", file=sys.stderr)
            return 2
        ex.spin_once(timeout_sec=0.02)
    relayed = [0]

    def got(m):
        pub.publish(m)
        relayed[0] += 1

    node.create_subscription(msg_type(a.type), a.topic_in, got, qos)
    if a.ready:
        open(a.ready, "w").close()
    t0 = time.monotonic()
    last = None
    while True:
        n = relayed[0]
        ex.spin_once(timeout_sec=0.05)
        now = time.monotonic()
        if relayed[0] != n:
            last = now
        if last is not None and now - last > a.idle_s:
            break
        if now - t0 > a.timeout_s:
            break
    print(f"relay: {relayed[0]} relayed from {a.topic_in} to {a.topic_out}", file=sys.stderr, flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
