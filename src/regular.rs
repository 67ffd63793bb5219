//! The one check of every file a user names for netfi to read: a regular
//! file, opened without blocking and checked on the open descriptor. A
//! leaf: the capture reader and the scenario loader both build on it.

use std::io::Read;
use std::path::Path;

/// What a file netfi is told to read turned out to be instead of a regular
/// file; carried inside the `io::Error` of [`open_regular`] (kind
/// `InvalidInput`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{0}: only regular files are read")]
pub struct NotRegular(pub &'static str);

/// Opens `path` for reading if it is a regular file: the one check of every
/// file a user names for netfi to read (a scenario, the files its stages
/// name, a capture, a study, a run's directory, a bag, …). It is opened
/// without blocking (a FIFO without a writer would block the open for
/// ever) and without becoming a controlling terminal, and checked on the
/// open descriptor (`fstat`), so what is read is what was checked. A
/// directory, device, FIFO or socket is an `InvalidInput` error holding
/// [`NotRegular`]; `O_NONBLOCK` does nothing to reads of a regular file.
pub fn open_regular(path: &Path) -> std::io::Result<std::fs::File> {
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    let file = std::fs::OpenOptions::new().read(true).custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY).open(path)?;
    let t = file.metadata()?.file_type();
    let other = if t.is_file() {
        return Ok(file);
    } else if t.is_dir() {
        "a directory"
    } else if t.is_char_device() || t.is_block_device() {
        "a device"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    };
    Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, NotRegular(other)))
}

/// `std::fs::read` for a regular file only ([`open_regular`]).
pub fn read_file(path: &Path) -> std::io::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    open_regular(path)?.read_to_end(&mut bytes)?;
    Ok(bytes)
}

/// An error of [`open_regular`] in words: what the file is, or `cannot
/// read: …`.
pub fn open_error(e: &std::io::Error) -> String {
    match e.get_ref().and_then(|inner| inner.downcast_ref::<NotRegular>()) {
        Some(not) => not.to_string(),
        None => format!("cannot read: {e}"),
    }
}

/// Reads the regular file `path` ([`open_regular`]), of at most
/// `max_bytes`; the error says what was found instead (and is to be
/// prefixed with the file's name).
pub fn read_regular(path: &Path, max_bytes: u64) -> Result<Vec<u8>, String> {
    read_open(open_regular(path).map_err(|e| open_error(&e))?, max_bytes)
}

/// Reads a file [`open_regular`] opened, of at most `max_bytes`.
pub fn read_open(file: std::fs::File, max_bytes: u64) -> Result<Vec<u8>, String> {
    let len = file.metadata().map_err(|e| format!("cannot read: {e}"))?.len();
    let too_large = |n: u64| format!("{n} bytes: at most {max_bytes} are read (a larger file is not one netfi wrote or ships)");
    if len > max_bytes {
        return Err(too_large(len));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(max_bytes + 1).read_to_end(&mut bytes).map_err(|e| format!("cannot read: {e}"))?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

