//! The shell script: notes as comments, the distribution table, the `tc`
//! command; every word from the user or a file quoted.

use super::qdisc::Netem;
use crate::cli::ExportNetemArgs;
use anyhow::{bail, Result};
use std::fmt::Write;

/// The script: notes as comments, the distribution table if one is
/// needed, and the `tc` command. Everything taken from the user or a file
/// goes in quoted (words) or with its line breaks escaped (comments): the
/// script is meant to run as root.
pub(super) fn write_script(args: &ExportNetemArgs, name: &str, netem: &Netem, limit: u64) -> Result<String> {
    validate_dev(&args.dev)?;
    let dev = quote(&args.dev)?;
    let mut out = String::new();
    writeln!(out, "#!/bin/sh").unwrap();
    writeln!(out, "# netem equivalent of netfi scenario {} (netfi {}).", comment(&format!("{name:?}")), netfi::fit::TOOL_VERSION).unwrap();
    for n in &netem.notes {
        writeln!(out, "# - {}", comment(n)).unwrap();
    }
    writeln!(out, "# Randomness differs: netem draws from the kernel's generator, not netfi's seeded streams.").unwrap();
    writeln!(out, "# To remove it: tc qdisc del dev {dev} root").unwrap();
    writeln!(out, "set -e").unwrap();
    if let Some((name, body)) = &netem.table {
        write_table(&mut out, args, name, body)?;
    }
    let mut cmd = format!("tc qdisc replace dev {dev} root netem limit {limit}");
    for text in netem.clauses() {
        cmd.push(' ');
        cmd.push_str(text);
    }
    writeln!(out, "{cmd}").unwrap();
    Ok(out)
}

/// The lines that put distribution table `name` where tc looks for it.
fn write_table(out: &mut String, args: &ExportNetemArgs, name: &str, body: &str) -> Result<()> {
    // tc reads tables from $TC_LIB_DIR when set, else from the directory
    // it was built with, which differs between distributions: the script
    // looks for it where it runs.
    let dirs = match &args.table_dir {
        Some(d) => vec![path_text(d)?],
        None => table_dir_candidates(),
    };
    let quoted: Vec<String> = dirs.iter().map(|d| quote(d)).collect::<Result<_>>()?;
    writeln!(out, "if [ -z \"${{TC_LIB_DIR:-}}\" ]; then").unwrap();
    writeln!(out, "  for d in {}; do", quoted.join(" ")).unwrap();
    if args.table_dir.is_some() {
        writeln!(out, "    TC_LIB_DIR=\"$d\"").unwrap();
    } else {
        writeln!(out, "    if [ -f \"$d/normal.dist\" ]; then TC_LIB_DIR=\"$d\"; break; fi").unwrap();
    }
    writeln!(out, "  done").unwrap();
    writeln!(out, "fi").unwrap();
    writeln!(
        out,
        "if [ ! -d \"${{TC_LIB_DIR:-}}\" ]; then echo \"tc's distribution table directory was not found (looked in: {}); set TC_LIB_DIR\" >&2; exit 1; fi",
        comment(&dirs.join(" ")).replace(['"', '$', '`', '\\'], "?")
    )
    .unwrap();
    writeln!(out, "export TC_LIB_DIR").unwrap();
    writeln!(out, "cat > \"$TC_LIB_DIR/{name}.dist\" <<'NETFI_TABLE'").unwrap();
    out.push_str(body);
    writeln!(out, "NETFI_TABLE").unwrap();
    writeln!(out, "# To remove the table too: rm -f \"$TC_LIB_DIR/{name}.dist\"").unwrap();
    Ok(())
}

/// Where iproute2 installs tc's distribution tables: Debian and Ubuntu
/// under the multiarch directory (`/usr/lib/x86_64-linux-gnu/tc`), Fedora
/// and openSUSE under `/usr/lib64/tc`, iproute2's own default `/usr/lib/tc`.
/// Those found on this machine (with iproute2's `normal.dist`) come first;
/// the script tries each in turn where it runs.
const TABLE_DIRS: [&str; 4] = ["/usr/lib/x86_64-linux-gnu/tc", "/usr/lib/aarch64-linux-gnu/tc", "/usr/lib64/tc", "/usr/lib/tc"];

fn table_dir_candidates() -> Vec<String> {
    let mut dirs: Vec<String> = Vec::new();
    // Other multiarch directories present here.
    if let Ok(rd) = std::fs::read_dir("/usr/lib") {
        let mut found: Vec<String> = rd
            .filter_map(|e| e.ok())
            .map(|e| e.path().join("tc"))
            .filter(|p| p.join("normal.dist").is_file())
            .filter_map(|p| p.to_str().map(str::to_owned))
            .collect();
        found.sort();
        dirs.extend(found);
    }
    for d in TABLE_DIRS {
        if !dirs.iter().any(|x| x == d) {
            dirs.push(d.to_owned());
        }
    }
    let here = |d: &String| std::path::Path::new(d).join("normal.dist").is_file();
    dirs.sort_by_key(|d| !here(d));
    if !dirs.iter().any(here) {
        eprintln!(
            "warning: tc's distribution tables were not found on this machine (looked in {}); the script looks again where it runs, or set TC_LIB_DIR",
            dirs.join(", ")
        );
    }
    dirs
}

/// Checks a network interface name by the kernel's own rule
/// (`dev_valid_name`): 1 to 15 bytes, not `.` or `..`, no `/`, `:` or
/// white space. Anything else the kernel allows (`$`, `;`, quotes) is legal
/// and is quoted in the script.
fn validate_dev(dev: &str) -> Result<()> {
    const IFNAMSIZ: usize = 16;
    if dev.is_empty() || dev.len() >= IFNAMSIZ {
        bail!("--dev {dev:?}: an interface name has 1 to {} bytes, this one {}", IFNAMSIZ - 1, dev.len());
    }
    if dev == "." || dev == ".." {
        bail!("--dev {dev:?}: `.` and `..` are not interface names");
    }
    if let Some(c) = dev.chars().find(|c| matches!(c, '/' | ':') || c.is_whitespace() || c.is_control()) {
        bail!("--dev {dev:?}: an interface name may not contain {c:?} (no `/`, `:`, white space or control characters)");
    }
    Ok(())
}

/// A word for `sh`, quoted where needed. `shlex` (already a dependency of
/// the build, and the quoting rust-lang's `cc` trusts) rather than a
/// hand-written quoter: it quotes everything a POSIX shell expands and
/// refuses a NUL, which no quoting can carry.
fn quote(word: &str) -> Result<String> {
    shlex::try_quote(word).map(|w| w.into_owned()).map_err(|e| anyhow::anyhow!("{word:?} cannot be quoted for the shell: {e}"))
}

fn path_text(p: &std::path::Path) -> Result<String> {
    p.to_str().map(str::to_owned).ok_or_else(|| anyhow::anyhow!("--table-dir {}: not valid UTF-8", p.display()))
}

/// Text for a `#` comment: control characters (a line break would end the
/// comment and start a command) are written escaped.
fn comment(text: &str) -> String {
    text.chars().map(|c| if c.is_control() { c.escape_default().to_string() } else { c.to_string() }).collect()
}

