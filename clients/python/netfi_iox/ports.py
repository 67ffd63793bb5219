"""The ends of a run's channels: publishers and subscribers over
iceoryx2's ports, and waiting for a peer. Used by :mod:`netfi_iox.run`
(frames, feedback) and :mod:`netfi_iox.video`."""

import ctypes
import time

#: Every subscriber's queue, in frames; also the service's maximum.
SUBSCRIBER_BUFFER_FRAMES = 16_384
MAX_PUBLISHERS_PER_CHANNEL = 1
MAX_SUBSCRIBERS_PER_CHANNEL = 2
MAX_NODES_PER_CHANNEL = 8
PUBLISHER_MAX_LOANED_SAMPLES = 1
SUBSCRIBER_MAX_BORROWED_SAMPLES = 1
HISTORY_FRAMES = 0


class NoPeer(RuntimeError):
    """The expected peer did not appear in time."""


class _End:
    """What every end of a channel has: its service, its port, and
    :meth:`close`."""

    def __init__(self, service, port):
        self.service = service
        self.port = port

    def close(self) -> None:
        if self.port is not None:
            self.port.delete()
            self.port = None
        self.service = None


class PublishingEnd(_End):
    """A publishing end: its subscribers, and waiting for the first."""

    def peers_connected(self) -> int:
        """Subscribers of the channel now."""
        return self.service.dynamic_config.number_of_subscribers

    def wait_for_subscriber(self, timeout_s: float, node=None) -> None:
        """Waits until the channel has a subscriber (the next stage)."""
        deadline = time.monotonic() + timeout_s
        while self.peers_connected() == 0:
            if time.monotonic() > deadline:
                raise NoPeer(f"no subscriber on {self.service.name} within {timeout_s} s")
            if node is not None and node.termination_requested():
                raise NoPeer(f"stopped while waiting for a subscriber on {self.service.name}")
            time.sleep(0.001)


class SubscribingEnd(_End):
    """A subscribing end: its publishers."""

    def peers_connected(self) -> int:
        """Publishers of the channel now."""
        return self.service.dynamic_config.number_of_publishers


class Publisher(PublishingEnd):
    """A publisher of one channel; :meth:`send` copies a sample in."""

    def __init__(self, service, port, payload_type):
        super().__init__(service, port)
        self.payload_type = payload_type

    def send(self, sample, stamp=None) -> int:
        """Loans a slot, copies ``sample`` in, calls ``stamp(payload)`` on the
        shared-memory copy just before sending (e.g. to set ``send_ns``), and
        sends. Returns the number of subscribers that received it."""
        uninit = self.port.loan_uninit()
        loaned = uninit.write_payload(sample)
        if stamp is not None:
            stamp(loaned.payload().contents)
        return loaned.send()


class Subscriber(SubscribingEnd):
    """A subscriber of one channel; :meth:`receive_into` copies a sample out."""

    def __init__(self, service, port, payload_type):
        super().__init__(service, port)
        self.payload_type = payload_type

    def receive_into(self, out) -> bool:
        """Copies the next sample into ``out`` and releases it; False when
        none is waiting."""
        sample = self.port.receive()
        if sample is None:
            return False
        ctypes.memmove(ctypes.byref(out), sample.payload_ptr, ctypes.sizeof(out))
        sample.delete()
        return True

