"""Joining a netfi run over iceoryx2: the configuration, names and service
attributes of interface version 1 (docs/interface.md), and a node that opens
a run's ports with them."""

import ctypes
import gc
import os
import stat
from typing import Optional, Tuple, Type

import iceoryx2 as iox

from .payload import INTERFACE_VERSION, FeedbackSample, FrameSample
from .ports import (  # noqa: F401 (re-exported)
    HISTORY_FRAMES, MAX_NODES_PER_CHANNEL, MAX_PUBLISHERS_PER_CHANNEL, MAX_SUBSCRIBERS_PER_CHANNEL,
    PUBLISHER_MAX_LOANED_SAMPLES, SUBSCRIBER_BUFFER_FRAMES, SUBSCRIBER_MAX_BORROWED_SAMPLES,
    NoPeer, Publisher, PublishingEnd, Subscriber, SubscribingEnd,
)

#: The channels of a run: the last component of each service name. The
#: video channels carry ``[u8]`` slices with a ``netfi::VideoHeader.v1``
#: header (:mod:`netfi_iox.video`; :meth:`RunNode.video_publisher`,
#: :meth:`RunNode.video_subscriber`).
CHANNELS = ("console", "emulator", "direct", "feedback", "feedback_out", "video", "video_out")
#: The roles a node may take: the last component of its node name.
ROLES = ("console", "emulator", "simulator", "tool")


#: Where a run's iceoryx2 files live, and under which names.
#:
#: ``shared``: prefix ``netfi_<run>_`` under iceoryx2's own ``/tmp/iceoryx2/``.
#: ``per-user``: prefix ``netfi_u<uid>_<run>_`` under the user's own directory
#: (mode 0700), found as netfi finds it (:func:`user_root_dir`).
LAYOUTS = ("shared", "per-user")

#: The layout of the netfi build this module ships with. The environment
#: variable ``NETFI_IOX_LAYOUT`` overrides it; the Rust test ``tests/python``
#: checks that the two agree.
DEFAULT_LAYOUT = "per-user"

_RUN_ID_MAX_LEN = 48


class InterfaceMismatch(RuntimeError):
    """The run's service carries another payload type or attributes than
    this client speaks: it was refused rather than misread."""


def check_run_id(run_id: str) -> str:
    """Validates a run id: 1 to 48 ASCII letters, digits, ``_`` or ``-``."""
    if not run_id:
        raise ValueError("run id is empty; use 1 to 48 ASCII letters, digits, `_` or `-`")
    if len(run_id) > _RUN_ID_MAX_LEN:
        raise ValueError(f"run id `{run_id}` is {len(run_id)} bytes long; at most 48 are accepted")
    for i, ch in enumerate(run_id):
        if not (ch.isascii() and (ch.isalnum() or ch in "_-")):
            raise ValueError(f"run id `{run_id}` contains {ch!r} at byte {i}; only ASCII letters, digits, `_` and `-` are accepted")
    return run_id


def file_layout() -> str:
    """The layout in force: ``NETFI_IOX_LAYOUT`` or :data:`DEFAULT_LAYOUT`."""
    chosen = os.environ.get("NETFI_IOX_LAYOUT", DEFAULT_LAYOUT)
    if chosen not in LAYOUTS:
        raise ValueError(f"NETFI_IOX_LAYOUT={chosen!r}; expected one of {', '.join(LAYOUTS)}")
    return chosen


def location(run_id: str, which: Optional[str] = None) -> Tuple[str, str]:
    """The iceoryx2 root directory and file prefix of run ``run_id``.

    This is the one place that knows the convention; everything else asks it.
    """
    check_run_id(run_id)
    which = which or file_layout()
    if which == "per-user":
        return user_root_dir(), f"netfi_u{os.geteuid()}_{run_id}_"
    return "/tmp/iceoryx2/", f"netfi_{run_id}_"


#: The longest root directory netfi accepts, in bytes (iceoryx2's path limit).
_ROOT_MAX_LEN = 96


def _is_private(path: str) -> bool:
    """A directory (not a link) of this user, closed to others."""
    try:
        st = os.lstat(path)
    except OSError:
        return False
    return stat.S_ISDIR(st.st_mode) and st.st_uid == os.geteuid() and st.st_mode & 0o077 == 0


def _usable(path: str) -> bool:
    return os.path.isabs(path) and len(os.fsencode(path)) <= _ROOT_MAX_LEN


def user_root_dir() -> str:
    """This user's iceoryx2 root directory, with a trailing ``/``, chosen
    in netfi's order (docs/interface.md, "Where the files live"):

    1. ``$NETFI_IPC_ROOT`` when it names a private directory of this user
       (``netfi run`` sets it for the processes it starts);
    2. ``$XDG_RUNTIME_DIR/netfi-iceoryx2`` when ``$XDG_RUNTIME_DIR`` is a
       private directory of this user;
    3. ``/tmp/netfi-iceoryx2-<uid>``;
    4. where those are taken by someone else, the first private
       ``/tmp/netfi-iceoryx2-<uid>-*`` of this user, by name.

    A usual place that does not exist yet is created (mode 0700), as netfi
    creates it; one that exists but is not private is passed over.
    """
    named = os.environ.get("NETFI_IPC_ROOT", "")
    if named and _usable(named) and _is_private(named):
        return named.rstrip("/") + "/"
    uid = os.geteuid()
    usual = []
    xdg = os.environ.get("XDG_RUNTIME_DIR", "")
    if xdg and os.path.isabs(xdg) and _is_private(xdg):
        usual.append(os.path.join(xdg, "netfi-iceoryx2"))
    usual.append(f"/tmp/netfi-iceoryx2-{uid}")
    for path in filter(_usable, usual):
        try:
            os.mkdir(path, 0o700)
        except FileExistsError:
            pass
        except FileNotFoundError:
            continue
        if _is_private(path):
            return path + "/"
    stem = f"netfi-iceoryx2-{uid}-"
    for name in sorted(os.listdir("/tmp")):
        path = os.path.join("/tmp", name)
        if name.startswith(stem) and _is_private(path):
            return path + "/"
    raise NoPeer(f"no private iceoryx2 directory of uid {uid}: /tmp/netfi-iceoryx2-{uid} is taken by another user "
                 "and no replacement exists yet; start netfi first, it makes one")


def service_name(run_id: str, channel: str) -> str:
    """``netfi/<run>/<channel>``."""
    if channel not in CHANNELS:
        raise ValueError(f"unknown channel {channel!r}; expected one of {', '.join(CHANNELS)}")
    return f"netfi/{check_run_id(run_id)}/{channel}"


def node_name(run_id: str, role: str) -> str:
    """``netfi/<run>/<role>``."""
    if role not in ROLES:
        raise ValueError(f"unknown role {role!r}; expected one of {', '.join(ROLES)}")
    return f"netfi/{check_run_id(run_id)}/{role}"


def _ensure_private_dir(path: str) -> None:
    """Creates ``path`` 0700 if missing; refuses one that is not a private
    directory of this user (as netfi itself does)."""
    try:
        os.mkdir(path, 0o700)
    except FileExistsError:
        pass
    st = os.lstat(path)
    uid = os.geteuid()
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != uid or st.st_mode & 0o077:
        raise PermissionError(
            f"{path} is not a private directory of uid {uid} (owner {st.st_uid}, mode {st.st_mode & 0o7777:o}); remove it"
        )


def iceoryx2_config(run_id: str, which: Optional[str] = None) -> "iox.config.Config":
    """The explicit iceoryx2 configuration of run ``run_id``: iceoryx2's
    compiled-in defaults (no configuration file is read), the run's root and
    prefix, automatic dead-node clean-ups off, and the publish/subscribe
    defaults of the interface."""
    root, prefix = location(run_id, which)
    config = iox.config.default()
    g = config.global_cfg  # a view: writes go through to config
    g.prefix = iox.FileName.new(prefix)
    g.root_path = iox.Path.new(root)
    g.node.cleanup_dead_nodes_on_creation = False
    g.node.cleanup_dead_nodes_on_destruction = False
    g.service.cleanup_dead_nodes_on_open = False
    ps = config.defaults.publish_subscribe
    ps.max_publishers = MAX_PUBLISHERS_PER_CHANNEL
    ps.max_subscribers = MAX_SUBSCRIBERS_PER_CHANNEL
    ps.max_nodes = MAX_NODES_PER_CHANNEL
    ps.subscriber_max_buffer_size = SUBSCRIBER_BUFFER_FRAMES
    ps.subscriber_max_borrowed_samples = SUBSCRIBER_MAX_BORROWED_SAMPLES
    ps.publisher_max_loaned_samples = PUBLISHER_MAX_LOANED_SAMPLES
    ps.publisher_history_size = HISTORY_FRAMES
    ps.enable_safe_overflow = False
    ps.backpressure_strategy = iox.BackpressureStrategy.DiscardData
    return config


def _type_of(t) -> Tuple[str, int, int]:
    return iox.get_type_name(t), ctypes.sizeof(t), ctypes.alignment(t)


class RunNode:
    """This process's node in a run, and the factory of its ports.

    Use as a context manager, or call :meth:`close`: the node's files are
    removed on close, and the last node of a run removes the run's
    management segment from ``/dev/shm``.
    """

    def __init__(self, run_id: str, role: str, which: Optional[str] = None):
        self.run_id = check_run_id(run_id)
        self.role = role
        self.layout = which or file_layout()
        self.root, self.prefix = location(run_id, self.layout)
        if self.layout == "per-user":
            _ensure_private_dir(self.root)
        self.config = iceoryx2_config(run_id, self.layout)
        self._services = {}
        self._ports = []
        self._termination = False
        self.node = (
            iox.NodeBuilder.new()
            .name(iox.NodeName.new(node_name(run_id, role)))
            .config(self.config)
            .signal_handling_mode(iox.SignalHandlingMode.HandleTerminationRequests)
            .create(iox.ServiceType.Ipc)
        )
        # iceoryx2 creates the run's management segment 0666: the run's
        # processes are all this user's, so nobody else needs it.
        make_private(self.prefix)
        # Installs iceoryx2's signal capture now: from here on SIGINT and
        # SIGTERM are seen through termination_requested(), not as
        # KeyboardInterrupt.
        self.termination_requested()

    def __enter__(self) -> "RunNode":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def termination_requested(self) -> bool:
        """Whether SIGINT or SIGTERM has arrived (latched)."""
        if not self._termination:
            try:
                self.node.wait(iox.Duration.from_nanos(0))
            except iox.NodeWaitFailure as e:
                if "Interrupt" not in str(e) and "Interrupt" not in repr(e):
                    self._termination = True
        return self._termination

    def service(self, channel: str, payload_type: Type[ctypes.Structure] = FrameSample):
        """Opens (or creates) the service of ``channel`` with every limit of
        the interface stated, so that a service with another payload type or
        other limits is refused instead of adopted."""
        key = (channel, payload_type)
        if key in self._services:
            return self._services[key]
        name = service_name(self.run_id, channel)
        try:
            svc = (
                self.node.service_builder(iox.ServiceName.new(name))
                .publish_subscribe(payload_type)
                .max_publishers(MAX_PUBLISHERS_PER_CHANNEL)
                .max_subscribers(MAX_SUBSCRIBERS_PER_CHANNEL)
                .max_nodes(MAX_NODES_PER_CHANNEL)
                .subscriber_max_buffer_size(SUBSCRIBER_BUFFER_FRAMES)
                .subscriber_max_borrowed_samples(SUBSCRIBER_MAX_BORROWED_SAMPLES)
                .history_size(HISTORY_FRAMES)
                .enable_safe_overflow(False)
                .open_or_create()
            )
        except iox.PublishSubscribeOpenOrCreateError as e:
            raise self._explain(name, payload_type, e) from e
        self._services[key] = svc
        return svc

    def _explain(self, name: str, payload_type, error) -> Exception:
        """Turns iceoryx2's refusal into a message naming both sides' payloads."""
        ours = "{} ({} bytes, aligned to {})".format(*_type_of(payload_type))
        theirs = self.existing_payload(name)
        if theirs is None:
            return InterfaceMismatch(f"cannot open {name} with payload {ours}: iceoryx2 refused ({error!r})")
        tname, size, align = theirs
        if (tname, size, align) == _type_of(payload_type):
            return InterfaceMismatch(
                f"{name} carries {ours} like this client, but other attributes than interface "
                f"v{INTERFACE_VERSION}: refused (iceoryx2: {error!r})"
            )
        return InterfaceMismatch(
            f"{name} carries {tname} ({size} bytes, aligned to {align}), this client speaks {ours}: "
            f"refused (iceoryx2: {error!r}); use a client of the run's version ({tname.rsplit('.', 1)[-1]})"
        )

    def existing_payload(self, name: str) -> Optional[Tuple[str, int, int]]:
        """The payload type name, size and alignment of the existing service
        ``name``, read from its static configuration file (the Python
        bindings do not expose it)."""
        attrs = self.existing_service(name)
        if attrs is None:
            return None
        try:
            payload = attrs["messaging_pattern"]["PublishSubscribe"]["message_type_details"]["payload"]
            return str(payload["type_name"]), int(payload["size"]), int(payload["alignment"])
        except (KeyError, TypeError, ValueError):
            return None

    def existing_service(self, name: str) -> Optional[dict]:
        """The static configuration of the existing service ``name``, if any."""
        import glob
        import tomllib

        pattern = os.path.join(self.root, "services", glob.escape(self.prefix) + "*.service")
        for path in glob.glob(pattern):
            try:
                with open(path, "rb") as f:
                    doc = tomllib.load(f)
            except (OSError, ValueError):
                continue
            if doc.get("service_name") == name:
                return doc
        return None

    def publisher(self, channel: str, payload_type: Type[ctypes.Structure] = FrameSample) -> "Publisher":
        """The publishing end of ``channel``."""
        svc = self.service(channel, payload_type)
        port = (
            svc.publisher_builder()
            .max_loaned_samples(PUBLISHER_MAX_LOANED_SAMPLES)
            .backpressure_strategy(iox.BackpressureStrategy.DiscardData)
            .create()
        )
        p = Publisher(svc, port, payload_type)
        self._ports.append(p)
        return p

    def subscriber(self, channel: str, payload_type: Type[ctypes.Structure] = FrameSample) -> "Subscriber":
        """A subscribing end of ``channel``."""
        svc = self.service(channel, payload_type)
        port = svc.subscriber_builder().buffer_size(SUBSCRIBER_BUFFER_FRAMES).create()
        s = Subscriber(svc, port, payload_type)
        self._ports.append(s)
        return s

    def video_service(self, channel: str):
        """Opens (or creates) the video service of ``channel`` (``video`` or
        ``video_out``) with every attribute of the interface stated: payload
        ``[u8]``, user header ``netfi::VideoHeader.v1``, the channel's
        limits (docs/interface.md, "Video")."""
        from . import video as v

        key = (channel, "video")
        if key in self._services:
            return self._services[key]
        subscribers, borrowed = v.channel_limits(channel)
        name = service_name(self.run_id, channel)
        try:
            svc = (
                self.node.service_builder(iox.ServiceName.new(name))
                .publish_subscribe(v.VIDEO_PAYLOAD)
                .user_header(v.VideoHeader)
                .max_publishers(MAX_PUBLISHERS_PER_CHANNEL)
                .max_subscribers(subscribers)
                .max_nodes(MAX_NODES_PER_CHANNEL)
                .subscriber_max_buffer_size(v.VIDEO_BUFFER_FRAMES)
                .subscriber_max_borrowed_samples(borrowed)
                .history_size(HISTORY_FRAMES)
                .enable_safe_overflow(False)
                .open_or_create()
            )
        except iox.PublishSubscribeOpenOrCreateError as e:
            raise InterfaceMismatch(
                f"cannot open {name} as [u8] with user header {v.VIDEO_HEADER_TYPE_NAME} "
                f"({v.VIDEO_HEADER_SIZE} bytes, aligned to {v.VIDEO_HEADER_ALIGNMENT}) and the attributes of "
                f"interface v{INTERFACE_VERSION}: refused (iceoryx2: {e!r})"
            ) from e
        self._services[key] = svc
        return svc

    def video_publisher(self, max_len: int, channel: str = "video") -> "VideoPublisher":
        """The publishing end of a video channel (a camera's: ``video``),
        for frames of at most ``max_len`` bytes; its memory starts at
        ``max_len`` bytes a sample (at most 256 KiB) and grows by powers of
        two for larger frames, as netfi's publishers do."""
        from . import video as v

        if max_len < 1:
            raise ValueError(f"a video publisher's largest frame must be at least 1 byte, got {max_len}")
        svc = self.video_service(channel)
        port = (
            svc.publisher_builder()
            .initial_max_slice_len(min(max_len, v.VIDEO_INITIAL_SLICE_BYTES))
            .allocation_strategy(iox.AllocationStrategy.PowerOfTwo)
            .max_loaned_samples(PUBLISHER_MAX_LOANED_SAMPLES)
            .backpressure_strategy(iox.BackpressureStrategy.DiscardData)
            .create()
        )
        p = v.VideoPublisher(svc, port, max_len)
        self._ports.append(p)
        return p

    def video_subscriber(self, channel: str = "video_out") -> "VideoSubscriber":
        """A subscribing end of a video channel (a viewer's: ``video_out``)."""
        from . import video as v

        svc = self.video_service(channel)
        port = svc.subscriber_builder().buffer_size(v.VIDEO_BUFFER_FRAMES).create()
        s = v.VideoSubscriber(svc, port)
        self._ports.append(s)
        return s

    def close(self) -> None:
        """Deregisters the ports and the node; the run's last node also
        removes the run's management segment."""
        for p in self._ports:
            p.close()
        self._ports.clear()
        self._services.clear()
        if self.node is not None:
            # The bindings have no explicit delete for a node: dropping the
            # last reference removes it.
            self.node = None
            gc.collect()
            remove_mgmt_segment_if_unused(self.config, self.prefix)


def _own_shm_files(prefix: str, suffix: str = ""):
    """This user's files in ``/dev/shm`` whose names start with ``prefix``
    and end with ``suffix``, each with its ``lstat``."""
    uid = os.geteuid()
    try:
        names = os.listdir("/dev/shm")
    except OSError:
        return
    for n in names:
        if n.startswith(prefix) and n.endswith(suffix):
            p = os.path.join("/dev/shm", n)
            try:
                st = os.lstat(p)
            except OSError:
                continue
            if st.st_uid == uid:
                yield p, st


def make_private(prefix: str) -> None:
    """Takes group and other permissions off this user's files in
    ``/dev/shm`` whose names start with ``prefix``, as netfi's own
    processes do."""
    for p, st in _own_shm_files(prefix):
        if stat.S_ISREG(st.st_mode) and st.st_mode & 0o077:
            try:
                os.chmod(p, st.st_mode & 0o700)
            except OSError:
                pass


def remove_mgmt_segment_if_unused(config, prefix: str) -> None:
    """Removes ``/dev/shm/<prefix>*.global_mgmt`` of this user when no node
    of the run is left, as netfi's own processes do."""
    try:
        states = iox.Node.list(iox.ServiceType.Ipc, config)
    except Exception:
        return
    if any(not isinstance(s, iox.NodeState.Dead) for s in states):
        return
    for p, _ in _own_shm_files(prefix, ".global_mgmt"):
        try:
            os.unlink(p)
        except OSError:
            pass
