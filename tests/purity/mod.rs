//! The sans-IO core never names a clock, a file, a thread, a socket or
//! iceoryx2 (ARCHITECTURE.md, docs/spec.md §1). This test reads the core's
//! source files and fails on the first that does, so the invariant is checked
//! by the build rather than by review.
//!
//! What counts as naming: a path `std::fs`, `std::time`, `std::thread` or
//! `std::net` (also written `::std::…`, with spaces around `::`, or inside a
//! grouped import such as `use std::{fmt, fs};`), or the word `iceoryx2`
//! anywhere in code. Comments are ignored, so docs may explain what the core
//! does not do.

use std::path::{Path, PathBuf};

/// The core: every file under these directories, and these files.
const CORE_DIRS: [&str; 3] = ["src/model", "src/scenario", "src/fit"];
const CORE_FILES: [&str; 8] = [
    "src/scheduler.rs",
    "src/injector.rs",
    "src/frame.rs",
    "src/check.rs",
    "src/stats.rs",
    "src/motion.rs",
    "src/kinematics.rs",
    "src/video.rs",
];
/// The one shell file inside a core directory: the fits' threading layer.
const SHELL_EXCEPTIONS: [&str; 1] = ["src/fit/run.rs"];

/// Modules of `std` the core must not name.
const FORBIDDEN_STD: [&str; 4] = ["fs", "time", "thread", "net"];

fn core_files() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files: Vec<PathBuf> = CORE_FILES.iter().map(|f| root.join(f)).collect();
    for dir in CORE_DIRS {
        collect_rs(&root.join(dir), &mut files);
    }
    files.retain(|f| !SHELL_EXCEPTIONS.iter().any(|e| f.ends_with(e)));
    files.sort();
    files.dedup();
    files
}

fn collect_rs(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let path = entry.expect("a directory entry").path();
        if path.is_dir() {
            collect_rs(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The source without comments (line, doc and nested block comments);
/// string and char literals are kept as they are, so a comment marker inside
/// a string does not hide the code after it.
fn strip_comments(src: &str) -> String {
    let b = src.as_bytes();
    let mut out = String::with_capacity(src.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'/' && b.get(i + 1) == Some(&b'/') {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
            let mut depth = 0;
            while i < b.len() {
                if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
                    depth += 1;
                    i += 2;
                } else if b[i] == b'*' && b.get(i + 1) == Some(&b'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
            out.push(' ');
        } else if b[i] == b'"' {
            let start = i;
            i += 1;
            while i < b.len() && b[i] != b'"' {
                i += if b[i] == b'\\' { 2 } else { 1 };
            }
            i += 1;
            out.push_str(&src[start..i.min(b.len())]);
        } else {
            let ch = src[i..].chars().next().expect("inside the text");
            out.push(ch);
            i += ch.len_utf8();
        }
    }
    out
}

/// Whitespace runs become one space, and none is left next to `::`, `{`,
/// `}` or `,`, so `std :: {\n fs }` reads `std::{fs}` while `use std` keeps
/// its words apart.
fn squeeze(code: &str) -> String {
    let mut words = code.split_whitespace().collect::<Vec<_>>().join(" ");
    for sep in ["::", "{", "}", ","] {
        loop {
            let next = words.replace(&format!(" {sep}"), sep).replace(&format!("{sep} "), sep);
            if next == words {
                break;
            }
            words = next;
        }
    }
    words
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// Every forbidden name in `src`, as found.
fn violations(src: &str) -> Vec<String> {
    let text = squeeze(&strip_comments(src));
    let mut found = Vec::new();
    // The word `iceoryx2`, in any position.
    let mut from = 0;
    while let Some(at) = text[from..].find("iceoryx2") {
        let at = from + at;
        let before = text[..at].chars().next_back();
        if !before.is_some_and(is_ident) {
            found.push("iceoryx2".to_string());
        }
        from = at + "iceoryx2".len();
    }
    // `std::` followed by a forbidden module, directly or inside a group.
    let mut from = 0;
    while let Some(at) = text[from..].find("std::") {
        let at = from + at;
        from = at + "std::".len();
        if text[..at].chars().next_back().is_some_and(is_ident) {
            continue;
        }
        let rest = &text[from..];
        if let Some(group) = rest.strip_prefix('{') {
            for item in top_level_items(group) {
                let head: String = item.chars().take_while(|c| is_ident(*c)).collect();
                if FORBIDDEN_STD.contains(&head.as_str()) {
                    found.push(format!("std::{{{head}}}"));
                }
            }
        } else {
            let head: String = rest.chars().take_while(|c| is_ident(*c)).collect();
            if FORBIDDEN_STD.contains(&head.as_str()) {
                found.push(format!("std::{head}"));
            }
        }
    }
    found
}

/// The comma-separated items of a `{…}` group whose opening brace is already
/// consumed, up to its closing brace (nested groups stay inside their item).
fn top_level_items(group: &str) -> Vec<&str> {
    let mut items = Vec::new();
    let mut depth = 0;
    let mut start = 0;
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => {
                items.push(&group[start..i]);
                return items;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => {
                items.push(&group[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    items.push(&group[start..]);
    items
}

#[test]
fn the_core_names_no_clock_file_thread_socket_or_iceoryx2() {
    let files = core_files();
    assert!(files.len() >= 25, "the core should be found: {files:?}");
    let mut bad = Vec::new();
    for f in &files {
        let src = std::fs::read_to_string(f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        for v in violations(&src) {
            bad.push(format!("{}: names {v}", f.display()));
        }
    }
    assert!(bad.is_empty(), "the sans-IO core must stay pure:\n{}", bad.join("\n"));
}

#[test]
fn the_check_catches_every_form() {
    for src in [
        "use std::fs;",
        "use std::fs::File;",
        "let t = std::time::Instant::now();",
        "use ::std::thread;",
        "use std :: net :: UdpSocket;",
        "use std::{fmt, fs};",
        "use std::{\n    collections::BTreeMap,\n    time::Duration,\n};",
        "use std::{io::{self, Read}, thread::spawn};",
        "use iceoryx2::prelude::*;",
        "type S = iceoryx2::port::Publisher;",
        "let s = \"// not a comment\"; use std::fs;",
    ] {
        assert!(!violations(src).is_empty(), "not caught: {src}");
    }
    for src in [
        "use std::fmt;",
        "use std::sync::OnceLock;",
        "use std::{fmt, collections::BTreeMap};",
        "// use std::fs;\n/// reads no std::time\nfn f() {}",
        "/* std::thread /* nested */ iceoryx2 */ fn g() {}",
        "use core::time::Duration as _Unused; fn timeline() {}",
        "let filesystem = 1; let my_std = 2;",
    ] {
        assert!(violations(src).is_empty(), "false alarm on {src}: {:?}", violations(src));
    }
}
