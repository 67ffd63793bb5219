//! Two hosts on one machine for the tests that cross a network: the
//! console and the robot in network namespaces of their own, joined only
//! through a third where the emulator runs, by two veth pairs (console
//! `192.0.2.1` ↔ emulator `192.0.2.2`, emulator `198.51.100.1` ↔ robot
//! `198.51.100.2`: documentation ranges that exist only inside these
//! namespaces). No namespace forwards. Removed again when dropped.
//!
//! Needs root (or CAP_SYS_ADMIN and CAP_NET_ADMIN) and `ip` (iproute2).

use std::process::Command;

/// Runs `ip ARGS`; `Err` with its message if it fails.
pub fn ip(args: &[&str]) -> Result<(), String> {
    let o = Command::new("ip").args(args).output().map_err(|e| format!("cannot run `ip`: {e}"))?;
    if o.status.success() {
        Ok(())
    } else {
        Err(format!("`ip {}` failed: {}", args.join(" "), String::from_utf8_lossy(&o.stderr).trim()))
    }
}

/// The three namespaces and their links; removed when dropped.
pub struct Hosts {
    pub console: String,
    pub emu: String,
    pub robot: String,
}

impl Hosts {
    /// Builds the topology; `tag` (two letters) keeps the names of
    /// different test binaries apart; `default_routes` points each end's
    /// default route at the emulator's host (multicast discovery goes
    /// there). `Err` says why it could not be made.
    pub fn build(tag: &str, default_routes: bool) -> Result<Hosts, String> {
        let id = std::process::id() % 100_000;
        let h = Hosts { console: format!("{tag}-con-{id}"), emu: format!("{tag}-emu-{id}"), robot: format!("{tag}-rob-{id}") };
        ip(&["netns", "add", &h.console])?;
        // From here on, `h` removes whatever was made if a step fails.
        ip(&["netns", "add", &h.emu])?;
        ip(&["netns", "add", &h.robot])?;
        let (c0, c1, r0, r1) = (format!("{tag}c0-{id}"), format!("{tag}c1-{id}"), format!("{tag}r0-{id}"), format!("{tag}r1-{id}"));
        // Console side: c0 (console) ↔ c1 (emulator); robot side: r1 (emulator) ↔ r0 (robot).
        ip(&["link", "add", &c0, "netns", &h.console, "type", "veth", "peer", "name", &c1, "netns", &h.emu])?;
        ip(&["link", "add", &r0, "netns", &h.robot, "type", "veth", "peer", "name", &r1, "netns", &h.emu])?;
        for (ns, dev, addr) in [(&h.console, &c0, "192.0.2.1/24"), (&h.emu, &c1, "192.0.2.2/24"), (&h.emu, &r1, "198.51.100.1/24"), (&h.robot, &r0, "198.51.100.2/24")] {
            ip(&["-n", ns, "addr", "add", addr, "dev", dev])?;
            ip(&["-n", ns, "link", "set", dev, "up"])?;
        }
        for ns in [&h.console, &h.emu, &h.robot] {
            ip(&["-n", ns, "link", "set", "lo", "up"])?;
        }
        if default_routes {
            ip(&["-n", &h.console, "route", "add", "default", "via", "192.0.2.2"])?;
            ip(&["-n", &h.robot, "route", "add", "default", "via", "198.51.100.1"])?;
        }
        Ok(h)
    }
}

impl Hosts {
    /// [`Hosts::build`], or `None` where this machine cannot (not root, or
    /// no veth pairs), said on stderr; where `NETFI_REQUIRE_NETNS=1` that
    /// fails the test instead.
    pub fn or_skip(tag: &str, default_routes: bool) -> Option<Hosts> {
        let required = std::env::var("NETFI_REQUIRE_NETNS").as_deref() == Ok("1");
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } != 0 {
            assert!(!required, "NETFI_REQUIRE_NETNS=1 but this test does not run as root");
            eprintln!("skipping: network namespaces need root (or CAP_SYS_ADMIN and CAP_NET_ADMIN)");
            return None;
        }
        match Hosts::build(tag, default_routes) {
            Ok(h) => Some(h),
            Err(why) => {
                assert!(!required, "NETFI_REQUIRE_NETNS=1 but network namespaces joined by veth pairs cannot be made: {why}");
                eprintln!("skipping: this machine does not allow network namespaces joined by veth pairs: {why}");
                None
            }
        }
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        // Deleting a namespace deletes the veth ends in it (and so the pairs).
        for ns in [&self.console, &self.emu, &self.robot] {
            let _ = ip(&["netns", "del", ns]);
        }
    }
}
