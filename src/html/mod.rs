//! The run report as one self-contained HTML page (`netfi report DIR
//! --html` writes it to `DIR/report.html`): inline CSS and inline SVG
//! plots, no script, no URL of any kind, so it opens offline, mails as one
//! file, and a browser front end can serve the same page.
//!
//! The page is built from what a run leaves in its output directory
//! ([`inputs::RunInputs`]): `report.json` (with its `events` list of
//! control actions; for a run started by hand, the report assembled from
//! the services' own), `scenario.toml` (for the delay law), the
//! HdrHistogram logs and `trace.csv`, read as a stream into fixed-size
//! summaries. A missing or malformed file is an error naming it.
//!
//! Elements a test or a browser asserts on have stable ids: `run-id`,
//! `provenance` (and `prov-version`, `prov-command`, `prov-started`,
//! `prov-seed`, `prov-host`), `realized-loss` (its `data-value` is the
//! report's figure), `balanced`, `faults`, `missing` (the services'
//! reports not in the directory), `udp` (a run with a UDP side), `latency`, `delay-law`, `over-time`,
//! `loss-runs`, `kinematics`, `events`; every plot is an `<svg class="plot">` with its
//! own id.

mod added;
pub mod figures;
pub mod inputs;
mod page;
pub mod plot;
pub mod trace;
mod video;

use std::path::{Path, PathBuf};

/// Why a page could not be made.
#[derive(Debug, thiserror::Error)]
pub enum HtmlError {
    /// An input file is missing or unreadable.
    #[error("reading {}: {source}", path.display())]
    Read { path: PathBuf, source: std::io::Error },
    /// An input file is there but not what a run writes.
    #[error("{}: {what}", path.display())]
    Malformed { path: PathBuf, what: String },
    /// The page could not be written.
    #[error("writing {}: {source}", path.display())]
    Write { path: PathBuf, source: std::io::Error },
    /// The run's report could not be read or assembled.
    #[error(transparent)]
    Run(#[from] crate::service::report::DirError),
    /// A plot could not be drawn (its data out of its axes' reach).
    #[error("plot {id}: {message}")]
    Plot { id: String, message: String },
}

impl HtmlError {
    pub(crate) fn read(path: &Path, source: std::io::Error) -> HtmlError {
        HtmlError::Read { path: path.to_path_buf(), source }
    }
    pub(crate) fn malformed(path: &Path, what: impl Into<String>) -> HtmlError {
        HtmlError::Malformed { path: path.to_path_buf(), what: what.into() }
    }
}

/// The name of the page in the run's directory.
pub const FILE_NAME: &str = "report.html";

/// The page of the run in `dir`.
pub fn render(dir: &Path) -> Result<String, HtmlError> {
    let inputs = inputs::RunInputs::read(dir)?;
    page::page(&inputs)
}

/// Writes the page of the run in `dir` to `dir/report.html` (readable by
/// others, writable only by its owner) and returns its path.
pub fn write(dir: &Path) -> Result<PathBuf, HtmlError> {
    let html = render(dir)?;
    let path = dir.join(FILE_NAME);
    write_file(&path, html.as_bytes()).map_err(|source| HtmlError::Write { path: path.clone(), source })?;
    Ok(path)
}

/// Writes as `NAME.partial` renamed into place once whole
/// ([`crate::durable`]: never through a link planted at either name), so
/// a failed write never leaves half a page where a whole one was.
fn write_file(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    crate::durable::write_whole_mode(path, bytes, 0o644).map_err(std::io::Error::other)
}

/// `text` with `&`, `<`, `>`, `"` and `'` escaped, for an attribute or text.
/// A short "nothing here" paragraph where a section has no data.
fn none(text: &str) -> maud::Markup {
    maud::html! { p.none { (text) } }
}

pub(crate) fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}
