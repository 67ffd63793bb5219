//! The page's calls: preview, parse, and the runs (start, state, stop,
//! live control, report).

use super::runs::Start;
use super::Ui;
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::response::{Html, IntoResponse, Response};
use axum::Json;
use serde::Deserialize;
use std::sync::Arc;

fn unprocessable(msg: impl std::fmt::Display) -> Response {
    (StatusCode::UNPROCESSABLE_ENTITY, format!("{msg:#}")).into_response()
}

fn not_found(id: &str) -> Response {
    (StatusCode::NOT_FOUND, format!("no run `{id}` was started here")).into_response()
}

/// `POST /api/preview`'s body.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PreviewRequest {
    toml: String,
    #[serde(default = "default_frames")]
    frames: u64,
    #[serde(default = "default_rate")]
    rate_hz: f64,
    /// In brief, for the figures beside the stage numbered so on the page.
    #[serde(default)]
    stage: Option<u32>,
}

/// `POST /api/parse`'s body.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParseRequest {
    toml: String,
}

fn default_frames() -> u64 {
    100_000
}

fn default_rate() -> f64 {
    1000.0
}

/// `POST /api/preview` `{toml, frames, rate_hz, stage}`: the checker's
/// figures and plots as an HTML fragment (in brief with `stage`), or the
/// parser's error.
pub async fn preview(Json(q): Json<PreviewRequest>) -> Response {
    if !(1_000..=5_000_000).contains(&q.frames) {
        return unprocessable(format!("frames: between 1000 and 5000000, got {}", q.frames));
    }
    let done = tokio::task::spawn_blocking(move || match q.stage {
        Some(k) => super::preview::render_brief(&q.toml, q.frames, q.rate_hz, k),
        None => super::preview::render(&q.toml, q.frames, q.rate_hz),
    })
    .await;
    match done {
        Ok(Ok(html)) => Html(html).into_response(),
        Ok(Err(e)) => unprocessable(e),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("preview failed: {e}")).into_response(),
    }
}

/// `POST /api/parse` `{toml}`: the scenario as the builder holds it (its
/// file's tables as JSON), or the parser's error.
pub async fn parse(Json(ParseRequest { toml: body }): Json<ParseRequest>) -> Response {
    if let Err(e) = crate::scenario::parse_str(&body, "scenario", "scenario") {
        return unprocessable(e);
    }
    match toml::from_str::<toml::Value>(&body) {
        Ok(v) => Json(v).into_response(),
        Err(e) => unprocessable(e),
    }
}

/// `POST /api/runs` `{toml, duration_s, seed, rate_hz, return_scenario,
/// video_mbps, video_scenario, capture, isolate}`: starts a run; `{id}`.
pub async fn start(State(ui): State<Arc<Ui>>, Json(req): Json<Start>) -> Response {
    // Off the server's thread: a capture is read whole to be checked.
    match tokio::task::spawn_blocking(move || ui.runs.start(&ui.opts, &req)).await {
        Ok(Ok(id)) => Json(serde_json::json!({ "id": id })).into_response(),
        Ok(Err(e)) => unprocessable(e),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("{e}")).into_response(),
    }
}

/// `GET /api/runs/{id}`: the run's state (and its report once ended).
pub async fn status(State(ui): State<Arc<Ui>>, Path(id): Path<String>) -> Response {
    match ui.runs.status(&ui.opts.out_dir, &id) {
        Some(s) => Json(s).into_response(),
        None => not_found(&id),
    }
}

/// `POST /api/runs/{id}/stop` `{}`.
pub async fn stop(State(ui): State<Arc<Ui>>, Path(id): Path<String>, Json(_): Json<serde_json::Value>) -> Response {
    if ui.runs.status(&ui.opts.out_dir, &id).is_some_and(|s| s.state != "running") {
        return (StatusCode::CONFLICT, "the run has already ended").into_response();
    }
    if ui.runs.stop(&id) {
        StatusCode::NO_CONTENT.into_response()
    } else {
        not_found(&id)
    }
}

/// `POST /api/runs/{id}/ctl`: live control of a running run through its
/// control service (see [`super::live::Control`]); the emulator's answer,
/// or its error (the scenario parser's). A run that has ended is a 409
/// saying so.
pub async fn ctl(State(ui): State<Arc<Ui>>, Path(id): Path<String>, Json(req): Json<super::live::Control>) -> Response {
    let Some(out) = ui.runs.out_dir(&ui.opts.out_dir, &id) else { return not_found(&id) };
    if !ui.runs.is_running(&id) {
        return (StatusCode::CONFLICT, "the run has ended: live control steers a running run only").into_response();
    }
    let netfi = ui.opts.netfi.clone();
    match tokio::task::spawn_blocking(move || super::live::control(&netfi, &id, &out, &req)).await {
        Ok(Ok(answer)) => Json(answer).into_response(),
        Ok(Err(e)) => unprocessable(e),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("{e}")).into_response(),
    }
}

/// `GET /runs/{id}/report`: the run's report page (written on first
/// request once the run has ended).
pub async fn report(State(ui): State<Arc<Ui>>, Path(id): Path<String>) -> Response {
    let Some(out) = ui.runs.out_dir(&ui.opts.out_dir, &id) else { return not_found(&id) };
    if ui.runs.is_running(&id) {
        return (StatusCode::CONFLICT, "the run is still going: its report comes when it ends").into_response();
    }
    let page = tokio::task::spawn_blocking(move || {
        let path = out.join("report.html");
        if !path.exists() {
            crate::html::write(&out).map_err(super::UiError::from)?;
        }
        std::fs::read_to_string(&path).map_err(|cause| super::UiError::Read { path, cause })
    })
    .await;
    match page {
        Ok(Ok(html)) => Html(html).into_response(),
        Ok(Err(e)) => (StatusCode::INTERNAL_SERVER_ERROR, format!("{e:#}")).into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("{e}")).into_response(),
    }
}
