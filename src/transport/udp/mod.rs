//! UDP datagram ports: the emulator's endpoints when the console or the robot
//! speaks over the network (ITP over UDP, or any datagram protocol).
//!
//! # Contract
//!
//! - A [`UdpPort`] is one bound, non-blocking socket. Receiving and sending
//!   never block and allocate nothing: [`UdpPort::recv_from`] answers
//!   `Ok(None)` when nothing waits, and a kernel send buffer that is full is
//!   [`UdpSendError::WouldBlock`], for the caller to count.
//! - A receive reports the datagram's **true length**, even when the
//!   caller's buffer was shorter and only its first bytes were kept (the
//!   kernel is asked with `MSG_TRUNC`): a datagram of the wrong size can
//!   always be told from a right one.
//! - A port can be opened with `SO_REUSEADDR`, so it can sit on an address
//!   that a tool's wildcard listener also uses: Linux hands a datagram to the
//!   socket bound to its exact destination address before a wildcard one.
//! - What the kernel itself dropped because a receive buffer was full is
//!   not lost from view: [`UdpPort::kernel_drops`] reads the socket's drop
//!   counter (`/proc/net/udp`, `/proc/net/udp6`), off the hot path.
//! - A port can be given its one peer ([`UdpPort::accept_only`]): from
//!   then on a receive takes datagrams from that address only. Anything
//!   else is **refused**: taken off the socket, counted per sender
//!   ([`UdpPort::refused`]) and never handed over, with no allocation
//!   (a fixed table, [`ForeignSenders`]). This is how the emulator's
//!   ingress takes only its console's frames ([`ConsolePolicy`]) and its
//!   return path only the robot's datagrams (the egress port accepts only
//!   the robot's address). Unlike `connect(2)`, what is refused is counted,
//!   and a handle made by [`UdpPort::try_clone`] keeps the peer. An IPv4
//!   peer is the same peer when a dual-stack socket (bound to `[::]`) sees
//!   it as an IPv4-mapped address ([`peers::same_sender`]).
//!
//! Sockets here know nothing about frames, scenarios or the emulator; the
//! frame source and sink over them ([`UdpSource`], [`UdpSink`], with the
//! raw-mode [`Arena`]) are in [`frames`].

pub mod addr;
pub mod args;
pub mod frames;
pub mod peers;
pub mod report;
pub mod transport;
pub use args::{Payload, UdpArgs, UdpArgsError};
pub use frames::{Arena, UdpSink, UdpSource, ARENA_SLOT_BYTES};
pub use report::{BoundEndpoints, ForeignSender, OwnPercentiles, OwnTime, UdpReport};
pub use transport::{ConsoleAddr, ConsoleUnnamed, Udp, UdpSession, UdpSideError, RAW_DEFAULT_QUEUE_CAPACITY};

/// The name of the return path (what the robot sends back, relayed to the
/// console) in a lane's reports: its key in `emulator.json`'s paths and
/// `udp.json`'s `return_path`.
pub const RETURN_PATH: &str = "return";
pub use peers::{ConsolePolicy, ConsolePolicyError, ForeignSenders, Refused, RefusedSender, FOREIGN_SENDERS_NAMED};

use socket2::{Domain, Protocol, SockAddr, Socket, Type};
use std::cell::Cell;
use std::io;
use std::mem::MaybeUninit;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr};

/// Size of a buffer that holds any UDP payload: 64 KiB. The largest payload
/// is 65,507 bytes over IPv4 and 65,527 over IPv6 (without jumbograms).
pub const MAX_DATAGRAM_BYTES: usize = 1 << 16;

/// Default requested kernel buffer size of each UDP socket: 4 MiB, a
/// quarter of a second of 124-byte frames at 100 kHz (the kernel caps it at
/// `net.core.rmem_max`).
pub const DEFAULT_UDP_BUFFER_BYTES: usize = 4 << 20;

/// Options applied before the socket is bound.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct UdpOptions {
    /// Set `SO_REUSEADDR`, so a wildcard socket on the same port (another
    /// program's) does not prevent the bind, and neither does ours prevent
    /// theirs.
    pub reuse_address: bool,
    /// Requested size of the kernel's receive and send buffers in bytes
    /// (`SO_RCVBUF`, `SO_SNDBUF`); the kernel caps it at
    /// `net.core.rmem_max` / `wmem_max`. `None` keeps the system default.
    pub buffer_bytes: Option<usize>,
}

/// Why a port could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum UdpOpenError {
    /// The kernel refused to create a UDP socket (out of descriptors, or no
    /// such address family).
    #[error("creating a UDP socket for {addr}: {source}")]
    Create {
        /// The address the port was to be bound to.
        addr: SocketAddr,
        /// The kernel's error.
        #[source]
        source: io::Error,
    },
    /// A socket option could not be set (`option` names it).
    #[error("setting {option} on the UDP socket for {addr}: {source}")]
    Option {
        /// The address the port was to be bound to.
        addr: SocketAddr,
        /// The option, as its C name (`SO_RCVBUF`, …).
        option: &'static str,
        /// The kernel's error.
        #[source]
        source: io::Error,
    },
    /// The address could not be bound: in use by a socket without
    /// `SO_REUSEADDR`, not an address of this host (or of this network
    /// namespace), or a privileged port.
    #[error("binding UDP {addr}: {source} (is the port in use, or the address not on this host?)")]
    Bind {
        /// The address the port was to be bound to.
        addr: SocketAddr,
        /// The kernel's error.
        #[source]
        source: io::Error,
    },
    /// The socket is bound but its local address could not be read back.
    #[error("reading the local address of UDP {addr}: {source}")]
    LocalAddr {
        /// The address the port was to be bound to.
        addr: SocketAddr,
        /// The kernel's error.
        #[source]
        source: io::Error,
    },
}

/// Why a receive failed (nothing waiting is not a failure: `Ok(None)`).
#[derive(Debug, thiserror::Error)]
pub enum UdpRecvError {
    /// The kernel reported an error on the socket.
    #[error("receiving on UDP {local}: {source}")]
    Io {
        /// The port's local address.
        local: SocketAddr,
        /// The kernel's error.
        #[source]
        source: io::Error,
    },
    /// A datagram came from an address that is not IPv4 or IPv6 (cannot
    /// happen on a UDP/IP socket; reported rather than assumed).
    #[error("receiving on UDP {local}: a datagram from a non-IP address")]
    NotIp {
        /// The port's local address.
        local: SocketAddr,
    },
}

/// Why a datagram was not sent.
#[derive(Debug, thiserror::Error)]
pub enum UdpSendError {
    /// The socket's kernel send buffer is full; the datagram was not sent.
    #[error("sending {len} bytes from UDP {local} to {to}: the send buffer is full")]
    WouldBlock {
        /// The port's local address.
        local: SocketAddr,
        /// The destination.
        to: SocketAddr,
        /// Bytes offered.
        len: usize,
    },
    /// The datagram is larger than the path allows (`EMSGSIZE`).
    #[error("sending {len} bytes from UDP {local} to {to}: datagram too large for the path")]
    TooLarge {
        /// The port's local address.
        local: SocketAddr,
        /// The destination.
        to: SocketAddr,
        /// Bytes offered.
        len: usize,
    },
    /// The kernel sent fewer bytes than given (not expected of UDP).
    #[error("sending {len} bytes from UDP {local} to {to}: only {sent} were sent")]
    Truncated {
        /// The port's local address.
        local: SocketAddr,
        /// The destination.
        to: SocketAddr,
        /// Bytes offered.
        len: usize,
        /// Bytes sent.
        sent: usize,
    },
    /// Any other error from the kernel (no route, network unreachable, …).
    #[error("sending {len} bytes from UDP {local} to {to}: {source}")]
    Io {
        /// The port's local address.
        local: SocketAddr,
        /// The destination.
        to: SocketAddr,
        /// Bytes offered.
        len: usize,
        /// The kernel's error.
        #[source]
        source: io::Error,
    },
}

/// A destination, converted once into the kernel's address form so that
/// sending to it converts nothing.
#[derive(Debug, Clone)]
pub struct PeerAddr {
    addr: SocketAddr,
    raw: SockAddr,
}

impl PeerAddr {
    /// Converts `addr`.
    pub fn new(addr: SocketAddr) -> PeerAddr {
        PeerAddr { addr, raw: SockAddr::from(addr) }
    }

    /// The address.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }
}

impl From<SocketAddr> for PeerAddr {
    fn from(addr: SocketAddr) -> Self {
        PeerAddr::new(addr)
    }
}

/// A datagram that was received: its true length (which may exceed the
/// buffer it was received into) and its source.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Datagram {
    /// Bytes in the datagram (not only those kept).
    pub len: usize,
    /// Its source address.
    pub from: SocketAddr,
}

/// Refused datagrams one receive takes off the socket before it answers
/// "nothing waiting": a flood from strangers costs the caller a bounded
/// number of system calls per receive, and moves on with the queue.
pub const REFUSED_PER_RECEIVE: usize = 32;

/// One bound, non-blocking UDP socket.
#[derive(Debug)]
pub struct UdpPort {
    socket: Socket,
    local: SocketAddr,
    /// The only sender received from, once given.
    peer: Option<PeerAddr>,
    /// What came from anyone else. A `Cell`: a receive takes `&self`, and
    /// a port is used by one thread at a time.
    refused: Cell<ForeignSenders>,
}

impl UdpPort {
    /// Binds a non-blocking UDP socket to `addr` (port 0: an ephemeral port).
    pub fn bind(addr: SocketAddr, opts: &UdpOptions) -> Result<UdpPort, UdpOpenError> {
        let socket = Socket::new(Domain::for_address(addr), Type::DGRAM, Some(Protocol::UDP))
            .map_err(|source| UdpOpenError::Create { addr, source })?;
        let opt = |option: &'static str| move |source| UdpOpenError::Option { addr, option, source };
        socket.set_nonblocking(true).map_err(opt("O_NONBLOCK"))?;
        if opts.reuse_address {
            socket.set_reuse_address(true).map_err(opt("SO_REUSEADDR"))?;
        }
        if let Some(bytes) = opts.buffer_bytes {
            socket.set_recv_buffer_size(bytes).map_err(opt("SO_RCVBUF"))?;
            socket.set_send_buffer_size(bytes).map_err(opt("SO_SNDBUF"))?;
        }
        socket.bind(&SockAddr::from(addr)).map_err(|source| UdpOpenError::Bind { addr, source })?;
        let local = socket
            .local_addr()
            .map_err(|source| UdpOpenError::LocalAddr { addr, source })?
            .as_socket()
            .ok_or_else(|| UdpOpenError::LocalAddr { addr, source: io::Error::other("not an IP address") })?;
        Ok(UdpPort { socket, local, peer: None, refused: Cell::default() })
    }

    /// An ephemeral port on the address that reaches `peer` most directly:
    /// loopback for a loopback peer (so nothing off the host can send to
    /// it), else the unspecified address of the peer's family.
    pub fn bind_towards(peer: SocketAddr, opts: &UdpOptions) -> Result<UdpPort, UdpOpenError> {
        let ip = match peer.ip() {
            IpAddr::V4(v4) if v4.is_loopback() => IpAddr::V4(Ipv4Addr::LOCALHOST),
            IpAddr::V6(v6) if v6.is_loopback() => IpAddr::V6(Ipv6Addr::LOCALHOST),
            IpAddr::V4(_) => IpAddr::V4(Ipv4Addr::UNSPECIFIED),
            IpAddr::V6(_) => IpAddr::V6(Ipv6Addr::UNSPECIFIED),
        };
        UdpPort::bind(SocketAddr::new(ip, 0), opts)
    }

    /// A second handle on the same socket (one descriptor more), for a
    /// second owner that only receives, or only sends. It accepts the same
    /// peer, and counts what it refuses itself (from zero).
    pub fn try_clone(&self) -> Result<UdpPort, UdpOpenError> {
        let socket = self.socket.try_clone().map_err(|source| UdpOpenError::Create { addr: self.local, source })?;
        Ok(UdpPort { socket, local: self.local, peer: self.peer.clone(), refused: Cell::default() })
    }

    /// From now on, receives take datagrams from `peer` only; any other is
    /// refused and counted ([`UdpPort::refused`]).
    pub fn accept_only(&mut self, peer: SocketAddr) {
        self.peer = Some(PeerAddr::new(peer));
    }

    /// The only sender this port receives from, once given.
    pub fn peer(&self) -> Option<&PeerAddr> {
        self.peer.as_ref()
    }

    /// The datagrams this handle refused, per sender.
    pub fn refused(&self) -> ForeignSenders {
        self.refused.get()
    }

    /// The address the socket is bound to (with the real port when bound
    /// to port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    /// Receives one datagram into `buf` if one waits. The returned length is
    /// the datagram's true length; if it exceeds `buf.len()`, only the first
    /// `buf.len()` bytes were kept. With a peer ([`UdpPort::accept_only`]),
    /// datagrams from anyone else are refused and counted (up to
    /// [`REFUSED_PER_RECEIVE`] per call; their bytes may have been written
    /// into `buf`) and the answer is the peer's next datagram or `Ok(None)`.
    #[inline]
    pub fn recv_from(&self, buf: &mut [u8]) -> Result<Option<Datagram>, UdpRecvError> {
        for _ in 0..REFUSED_PER_RECEIVE {
            match self.recv_any(buf)? {
                Some(d) if self.peer.as_ref().is_some_and(|p| !peers::same_sender(p.addr(), d.from)) => {
                    let mut r = self.refused.get();
                    r.count(d.from);
                    self.refused.set(r);
                }
                got => return Ok(got),
            }
        }
        Ok(None)
    }

    #[inline]
    fn recv_any(&self, buf: &mut [u8]) -> Result<Option<Datagram>, UdpRecvError> {
        // SAFETY: `MaybeUninit<u8>` has the layout of `u8`, and the kernel
        // only writes initialized bytes into the buffer, so it stays a valid
        // `[u8]` for the caller.
        let uninit = unsafe { &mut *(buf as *mut [u8] as *mut [MaybeUninit<u8>]) };
        match self.socket.recv_from_with_flags(uninit, libc::MSG_TRUNC) {
            Ok((len, from)) => match from.as_socket() {
                Some(from) => Ok(Some(Datagram { len, from })),
                None => Err(UdpRecvError::NotIp { local: self.local }),
            },
            Err(e) if e.kind() == io::ErrorKind::WouldBlock || e.kind() == io::ErrorKind::Interrupted => Ok(None),
            Err(source) => Err(UdpRecvError::Io { local: self.local, source }),
        }
    }

    /// Sends `buf` as one datagram to `to`, without blocking.
    #[inline]
    pub fn send_to(&self, buf: &[u8], to: &PeerAddr) -> Result<(), UdpSendError> {
        let len = buf.len();
        match self.socket.send_to(buf, &to.raw) {
            Ok(sent) if sent == len => Ok(()),
            Ok(sent) => Err(UdpSendError::Truncated { local: self.local, to: to.addr, len, sent }),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                Err(UdpSendError::WouldBlock { local: self.local, to: to.addr, len })
            }
            Err(e) if e.raw_os_error() == Some(libc::EMSGSIZE) => {
                Err(UdpSendError::TooLarge { local: self.local, to: to.addr, len })
            }
            Err(source) => Err(UdpSendError::Io { local: self.local, to: to.addr, len, source }),
        }
    }

    /// The kernel's receive and send buffer sizes in bytes, as granted (Linux
    /// reports twice the requested size, for its bookkeeping).
    pub fn buffer_bytes(&self) -> (Option<usize>, Option<usize>) {
        (self.socket.recv_buffer_size().ok(), self.socket.send_buffer_size().ok())
    }

    /// Datagrams the kernel dropped on arrival at this socket because its
    /// receive buffer was full (or for a bad UDP checksum), since the socket
    /// was created; `None` where `/proc/net/udp*` cannot be read. Off the hot
    /// path: it reads and parses a file.
    pub fn kernel_drops(&self) -> Option<u64> {
        use std::os::fd::AsRawFd;
        // SAFETY: fstat on a descriptor this port owns, into a zeroed struct.
        let inode = unsafe {
            let mut st: libc::stat = std::mem::zeroed();
            if libc::fstat(self.socket.as_raw_fd(), &mut st) != 0 {
                return None;
            }
            st.st_ino
        };
        let table = if self.local.is_ipv4() { "/proc/net/udp" } else { "/proc/net/udp6" };
        let text = std::fs::read_to_string(table).ok()?;
        proc_net_udp_drops(&text, inode)
    }
}

/// The `drops` column of the row of `/proc/net/udp` whose `inode` is
/// `inode`. Columns: `sl local rem st tx:rx tr:when retrnsmt uid timeout
/// inode ref pointer drops`.
fn proc_net_udp_drops(text: &str, inode: u64) -> Option<u64> {
    text.lines().skip(1).find_map(|line| {
        let cols: Vec<&str> = line.split_whitespace().collect();
        (cols.get(9)?.parse::<u64>().ok()? == inode).then(|| cols.get(12)?.parse().ok())?
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn loopback() -> SocketAddr {
        "127.0.0.1:0".parse().unwrap()
    }

    #[test]
    fn a_datagram_goes_and_comes_with_its_true_length() {
        let a = UdpPort::bind(loopback(), &UdpOptions::default()).unwrap();
        let b = UdpPort::bind(loopback(), &UdpOptions { reuse_address: true, buffer_bytes: Some(1 << 20) }).unwrap();
        let mut buf = [0u8; 8];
        assert!(b.recv_from(&mut buf).unwrap().is_none(), "nothing sent yet");
        let to = PeerAddr::new(b.local_addr());
        a.send_to(&[7u8; 200], &to).unwrap();
        let t0 = std::time::Instant::now();
        let got = loop {
            if let Some(d) = b.recv_from(&mut buf).unwrap() {
                break d;
            }
            assert!(t0.elapsed().as_secs() < 5, "loopback datagram never arrived");
        };
        assert_eq!(got, Datagram { len: 200, from: a.local_addr() });
        assert_eq!(buf, [7u8; 8]);
        assert_eq!(b.kernel_drops(), Some(0));
        let (rcv, snd) = b.buffer_bytes();
        assert!(rcv.unwrap() > 0 && snd.unwrap() > 0);
    }

    #[test]
    fn a_taken_port_is_a_bind_error_naming_it() {
        let a = UdpPort::bind(loopback(), &UdpOptions::default()).unwrap();
        let e = UdpPort::bind(a.local_addr(), &UdpOptions::default()).unwrap_err();
        assert!(matches!(e, UdpOpenError::Bind { addr, .. } if addr == a.local_addr()), "{e}");
        assert!(e.to_string().contains(&a.local_addr().to_string()));
    }

    #[test]
    fn a_port_with_a_peer_refuses_and_counts_everyone_else_and_its_clone_too() {
        let (peer, stranger) = (UdpPort::bind(loopback(), &UdpOptions::default()).unwrap(), UdpPort::bind(loopback(), &UdpOptions::default()).unwrap());
        let mut b = UdpPort::bind(loopback(), &UdpOptions::default()).unwrap();
        b.accept_only(peer.local_addr());
        let to = PeerAddr::new(b.local_addr());
        for _ in 0..3 {
            stranger.send_to(b"evil", &to).unwrap();
        }
        peer.send_to(b"good", &to).unwrap();
        let mut buf = [0u8; 8];
        let t0 = std::time::Instant::now();
        let got = loop {
            if let Some(d) = b.recv_from(&mut buf).unwrap() {
                break d;
            }
            assert!(t0.elapsed().as_secs() < 5, "loopback datagram never arrived");
        };
        assert_eq!((got.from, &buf[..got.len]), (peer.local_addr(), &b"good"[..]));
        let r = b.refused().report();
        assert_eq!((r.datagrams, r.senders.len(), r.unnamed), (3, 1, 0));
        assert_eq!((r.senders[0].addr, r.senders[0].datagrams), (stranger.local_addr(), 3));
        // A second handle accepts the same peer and counts on its own.
        let c = b.try_clone().unwrap();
        assert_eq!(c.peer().map(PeerAddr::addr), Some(peer.local_addr()));
        stranger.send_to(b"evil", &to).unwrap();
        std::thread::sleep(std::time::Duration::from_millis(20));
        assert!(c.recv_from(&mut buf).unwrap().is_none());
        assert_eq!((c.refused().total, b.refused().total), (1, 3));
    }

    #[test]
    fn bind_towards_a_loopback_peer_stays_on_loopback() {
        let p = UdpPort::bind_towards("127.0.0.1:9".parse().unwrap(), &UdpOptions::default()).unwrap();
        assert!(p.local_addr().ip().is_loopback());
        assert_ne!(p.local_addr().port(), 0);
    }

    #[test]
    fn the_drops_column_is_found_by_inode() {
        let text = "  sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid  timeout inode ref pointer drops\n\
                    1: 0100007F:8CA0 00000000:0000 07 00000000:00000000 00:00000000 00000000     0        0 4242 2 0000000000000000 17\n\
                    2: 0100007F:8CA1 00000000:0000 07 00000000:00000000 00:00000000 00000000     0        0 4243 2 0000000000000000 0\n";
        assert_eq!(proc_net_udp_drops(text, 4242), Some(17));
        assert_eq!(proc_net_udp_drops(text, 4243), Some(0));
        assert_eq!(proc_net_udp_drops(text, 1), None);
    }
}
