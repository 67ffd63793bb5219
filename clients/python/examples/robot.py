#!/usr/bin/env python3
"""A Python robot for a netfi run over iceoryx2 (interface v1).

Receives the frames the emulator releases (channel ``emulator``), applies ITP
semantics to a pose per arm (commands apply only while the clutch is engaged;
positions and rotations are incremental, the grasp absolute), and, unless
``--no-direct``, integrates the console's direct copies (channel ``direct``)
too, to report how far the robot diverged. After each command it publishes
its state as feedback (channel ``feedback``, ``netfi::FeedbackSample.v1``;
``--no-feedback`` turns it off), which the emulator passes back to the
console through the return scenario. Ends on the emulator's
end-of-stream marker (or SIGINT/SIGTERM), then prints a JSON summary (also
``--out FILE``).

    python3 clients/python/examples/robot.py --run-id R --out robot.json
"""

import argparse
import os
import sys
import time
from dataclasses import asdict, dataclass, field
from typing import List

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import netfi_iox  # noqa: E402
from netfi_iox import FeedbackSample, FrameSample, ItpFrame, RunNode  # noqa: E402
from netfi_iox.cli import emit, quantiles, run_main  # noqa: E402


@dataclass
class ArmPose:
    """One arm's integrated pose, in ITP units (positions exact integers)."""

    x: int = 0
    y: int = 0
    z: int = 0
    rx: float = 0.0
    ry: float = 0.0
    rz: float = 0.0
    grasp: int = 0


@dataclass
class Integrator:
    """Follows one stream of frames (docs/spec.md §2, as netfi's simulator does)."""

    arms: List[ArmPose] = field(default_factory=lambda: [ArmPose(), ArmPose()])
    frames: int = 0
    applied: int = 0

    def apply(self, f: ItpFrame) -> None:
        self.frames += 1
        if f.surgeon_mode != netfi_iox.SURGEON_ENGAGED:
            return
        self.applied += 1
        for arm, p in enumerate(self.arms):
            p.x += f.delx[arm]
            p.y += f.dely[arm]
            p.z += f.delz[arm]
            p.rx += f.qx[arm]
            p.ry += f.qy[arm]
            p.rz += f.qz[arm]
            p.grasp = f.grasp[arm]


@dataclass
class RobotState:
    """What the robot knows after a command: the command it answers and its
    pose then. This is the content of the robot's feedback to the console."""

    console_index: int
    sequence: int
    send_ns: int
    recv_ns: int
    arms: List[ArmPose]


def robot_state(robot: Integrator, sample: FrameSample, frame: ItpFrame, recv_ns: int) -> RobotState:
    """The robot's state in answer to ``sample`` (received at ``recv_ns``)."""
    return RobotState(
        console_index=sample.console_index,
        sequence=frame.sequence,
        send_ns=sample.send_ns,
        recv_ns=recv_ns,
        arms=[ArmPose(**asdict(a)) for a in robot.arms],
    )


def feedback_of(state: RobotState, robot_index: int, sample: FrameSample, commands: int) -> FeedbackSample:
    """The feedback sample that carries ``state`` (the answer to ``sample``)."""
    fb = FeedbackSample()
    fb.robot_index = robot_index
    fb.console_index = state.console_index
    fb.sequence = state.sequence & 0xFFFFFFFF
    fb.command_send_ns = state.send_ns
    fb.command_ingress_ns = sample.ingress_ns
    fb.command_release_ns = sample.release_ns
    fb.command_injected_delay_ns = sample.injected_delay_ns
    fb.commands = commands
    for arm, p in enumerate(state.arms):
        fb.position[arm][0], fb.position[arm][1], fb.position[arm][2] = p.x, p.y, p.z
        fb.rotation[arm][0], fb.rotation[arm][1], fb.rotation[arm][2] = p.rx, p.ry, p.rz
        fb.grasp[arm] = p.grasp
    return fb


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run-id", required=True)
    ap.add_argument("--no-direct", action="store_true", help="do not follow the console's direct copies")
    ap.add_argument("--ready", help="create this file once subscribed (for scripts that start the console next)")
    ap.add_argument("--timeout-s", type=float, help="give up when no end marker came after this many seconds")
    ap.add_argument("--out", help="also write the JSON summary here")
    ap.add_argument("--no-feedback", action="store_true", help="do not publish feedback")
    a = ap.parse_args()

    robot, console = Integrator(), Integrator()
    received = received_direct = bad_checksum = wrong_size = 0
    released_by_emulator = sent_by_console = None
    seen, extra = [], []
    last_state = None
    feedback_sent = feedback_unsubscribed = 0
    with RunNode(a.run_id, "simulator") as node:
        port = node.subscriber("emulator")
        feedback = None if a.no_feedback else node.publisher("feedback", FeedbackSample)

        def stamp(f):
            f.send_ns = time.monotonic_ns()

        direct = None if a.no_direct else node.subscriber("direct")
        if a.ready:
            open(a.ready, "w").close()
        s, d = FrameSample(), FrameSample()
        t_start = last_frame = time.monotonic_ns()
        stop_at = None
        ended_by = None
        idle_turns = 0
        while ended_by is None:
            idle = True
            while port.receive_into(s):
                t = time.monotonic_ns()
                idle, last_frame = False, t
                if s.is_end():
                    released_by_emulator = s.console_index
                    continue
                received += 1
                seen.append(t - s.send_ns)
                extra.append(t - s.send_ns - s.injected_delay_ns)
                if s.len != netfi_iox.ITP_FRAME_LEN:
                    wrong_size += 1
                    continue
                f = ItpFrame.decode(bytes(s.wire), verify=False)
                if not f.checksum_ok():
                    bad_checksum += 1
                robot.apply(f)
                last_state = robot_state(robot, s, f, t)
                if feedback is not None:
                    if feedback.send(feedback_of(last_state, feedback_sent, s, received), stamp) == 0:
                        feedback_unsubscribed += 1
                    feedback_sent += 1
            while direct is not None and direct.receive_into(d):
                idle, last_frame = False, time.monotonic_ns()
                if d.is_end():
                    sent_by_console = d.console_index
                    continue
                received_direct += 1
                if d.len == netfi_iox.ITP_FRAME_LEN:
                    console.apply(ItpFrame.decode(bytes(d.wire), verify=False))
            now = time.monotonic_ns()
            if released_by_emulator is not None and (
                direct is None or sent_by_console is not None or direct.peers_connected() == 0
                or now - last_frame > 200_000_000
            ):
                ended_by = "end_marker"
            elif stop_at is None and node.termination_requested():
                stop_at = now
            elif stop_at is not None and now - last_frame > 200_000_000:
                ended_by = "signal"
            elif a.timeout_s is not None and now - t_start > a.timeout_s * 1e9:
                ended_by = "timeout"
            if idle:
                idle_turns += 1
                time.sleep(0.0001 if idle_turns > 10 else 0)
            else:
                idle_turns = 0
        t_end = time.monotonic_ns()
        if feedback is not None:
            feedback.send(netfi_iox.feedback_end_marker(feedback_sent))

    divergence = None
    if direct is not None and received_direct:
        divergence = [
            {k: getattr(r, k) - getattr(c, k) for k in ("x", "y", "z", "rx", "ry", "rz", "grasp")}
            for r, c in zip(robot.arms, console.arms)
        ]
    summary = {
        "interface": netfi_iox.TYPE_NAME,
        "run_id": a.run_id,
        "received": received,
        "released_by_emulator": released_by_emulator,
        "balanced": released_by_emulator == received,
        "received_direct": received_direct,
        "sent_by_console": sent_by_console,
        "wrong_size": wrong_size,
        "bad_checksum": bad_checksum,
        "applied": robot.applied,
        "pose": [asdict(p) for p in robot.arms],
        "console_pose": [asdict(p) for p in console.arms] if received_direct else None,
        "divergence": divergence,
        "last_state": asdict(last_state) if last_state else None,
        "feedback_sent": feedback_sent,
        "feedback_unsubscribed": feedback_unsubscribed,
        "delay_seen_us": quantiles(seen, mean=True),
        "end_to_end_extra_us": quantiles(extra, mean=True),
        "ended_by": ended_by,
        "duration_s": (t_end - t_start) / 1e9,
    }
    emit(summary, a.out)
    return 0 if ended_by != "timeout" else 3


if __name__ == "__main__":
    run_main("robot", main, (netfi_iox.InterfaceMismatch, ValueError))
