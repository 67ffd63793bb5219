//! `netfi ui`: a browser front end on loopback. It builds scenarios from
//! models with every parameter, presets and database targets; previews what
//! a scenario realizes in simulated time ([`crate::check`]); loads and saves
//! TOML; starts and stops runs (each a `netfi run` child process, so the
//! emulator never shares a process with the server) with the options of
//! `netfi run` a study sets; lists them; steers a running one (switch to a
//! preset or the scenario being built, now or at a time; go to a phase;
//! pause) and shows its report page ([`crate::html`]).
//!
//! The server is one thread (a current-thread tokio runtime) kept off the
//! emulator's core; every page asset is compiled into the binary, nothing is
//! fetched at run time. Work that takes longer than a request should block
//! (a preview) runs on tokio's blocking pool.
//!
//! It obeys its own page only ([`guard`]): a `Host` that is not its own is
//! refused (DNS rebinding), every request needs the token printed at start
//! (then held in a same-origin cookie), and every state change is a JSON
//! request with the page's own header, from its own origin.

mod api;
mod builder;
pub mod error;
pub mod guard;
mod live;
mod page;
mod preview;
mod runs;
mod study;

pub use error::UiError;
use std::future::IntoFuture;
use axum::routing::{get, post};
use axum::Router;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;

/// How `netfi ui` is set up.
#[derive(Debug, Clone)]
pub struct UiOptions {
    /// Where to listen (loopback by default).
    pub bind: SocketAddr,
    /// Parent directory of the runs' output directories.
    pub out_dir: PathBuf,
    /// The `netfi` executable that runs are started with.
    pub netfi: PathBuf,
    /// The core the runs' emulators use: the server keeps off it.
    pub emulator_core: usize,
    /// Serve without a token (loopback only).
    pub no_token: bool,
    /// Host names the server answers to besides `localhost` and addresses.
    pub allow_hosts: Vec<String>,
}

/// What the handlers share.
pub(crate) struct Ui {
    pub opts: UiOptions,
    pub runs: runs::Runs,
}

/// Serves until SIGINT/SIGTERM; stops the runs it started on the way out.
pub fn serve(opts: UiOptions) -> Result<(), UiError> {
    let token = if opts.no_token { None } else { Some(guard::new_token()?) };
    // Checked before anything listens: no token is for loopback only.
    guard::Guard::new(opts.bind, token.clone(), opts.allow_hosts.clone())?;
    let mask = runs::CpuMask::current().map_err(UiError::Mask)?;
    crate::service::args::check_core("--emulator-core", Some(opts.emulator_core), &crate::host::allowed_cores()).map_err(UiError::Core)?;
    keep_off_core(opts.emulator_core)?;
    if !opts.bind.ip().is_loopback() {
        eprintln!(
            "WARNING: netfi ui listens on {} — not loopback: whoever reaches this address and has the token can start runs on this host, \
             and plain HTTP carries the token in clear",
            opts.bind
        );
    }
    std::fs::create_dir_all(&opts.out_dir).map_err(|e| UiError::Create { path: opts.out_dir.clone(), cause: e })?;
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().map_err(UiError::Runtime)?;
    let ui = Arc::new(Ui { runs: runs::Runs::new(mask), opts });
    rt.block_on(async move {
        let listener = tokio::net::TcpListener::bind(ui.opts.bind).await.map_err(|e| UiError::Listen { addr: ui.opts.bind, cause: e })?;
        let addr = listener.local_addr().map_err(|e| UiError::Listen { addr: ui.opts.bind, cause: e })?;
        let guard = Arc::new(guard::Guard::new(addr, token, ui.opts.allow_hosts.clone())?);
        println!("netfi ui on {}", guard.url());
        let app = router(ui.clone(), guard);
        // A signal ends the serving at once: a browser's idle keep-alive
        // connection would hold a graceful shutdown open for ever.
        tokio::select! {
            served = axum::serve(listener, app).into_future() => served.map_err(UiError::Serve)?,
            () = shutdown() => {}
        }
        ui.runs.stop_all();
        Ok(())
    })
}

fn router(ui: Arc<Ui>, guard: Arc<guard::Guard>) -> Router {
    Router::new()
        .route("/", get(page::index))
        .route("/runs", get(page::runs))
        .route("/runs/{id}", get(page::run))
        .route("/runs/{id}/report", get(api::report))
        .route("/api/preview", post(api::preview))
        .route("/api/parse", post(api::parse))
        .route("/api/runs", post(api::start))
        .route("/api/runs/{id}", get(api::status))
        .route("/api/runs/{id}/stop", post(api::stop))
        .route("/api/runs/{id}/ctl", post(api::ctl))
        .route("/assets/app.js", get(page::script))
        .route("/assets/app.css", get(page::style))
        .route("/study", get(study::page))
        .route("/study/view", get(study::participant_view))
        .route("/api/study/status", get(study::status))
        .route("/api/study/start", post(study::start))
        .route("/api/study/stop", post(study::stop))
        .route("/api/study/mark", post(study::mark))
        .route("/api/study/answer", post(study::answer))
        .route("/assets/study.js", get(study::script))
        .with_state(ui)
        .layer(axum::middleware::from_fn_with_state(guard, guard::check))
}

async fn shutdown() {
    use tokio::signal::unix::{signal, SignalKind};
    let (Ok(mut int), Ok(mut term)) = (signal(SignalKind::interrupt()), signal(SignalKind::terminate())) else {
        return std::future::pending().await;
    };
    tokio::select! {
        _ = int.recv() => {},
        _ = term.recv() => {},
    }
}

/// Keeps this process (its threads start after this) off the emulator's
/// core; on a one-core host that cannot be, and is said loudly.
fn keep_off_core(emulator_core: usize) -> Result<(), UiError> {
    if crate::host::cores_except(emulator_core).is_none() {
        eprintln!("WARNING: netfi ui shares core {emulator_core} with the runs' emulators: there is no other core");
        return Ok(());
    }
    Ok(crate::host::placement::place("ui", None, Some(emulator_core))?)
}
