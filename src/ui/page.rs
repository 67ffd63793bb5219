//! The pages: the scenario builder (`/`), the list of runs (`/runs`) and a
//! run's page (`/runs/{id}`). Their script and style are compiled in
//! ([`script`], [`style`]).

use super::Ui;
use axum::extract::{Path, State};
use axum::http::header;
use axum::response::IntoResponse;
use maud::{html, Markup, PreEscaped, DOCTYPE};
use std::sync::Arc;

const APP_JS: &str = concat!(include_str!("assets/call.js"), include_str!("assets/app.js"), include_str!("assets/chain.js"));
const APP_CSS: &str = include_str!("assets/app.css");

/// A page of `netfi ui`: its head, the header with the navigation, `body`,
/// and its script (`/assets/app.js` or a page's own).
pub(super) fn shell_with(title: &str, page: &str, script: &str, body: Markup) -> Markup {
    html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                meta name="viewport" content="width=device-width, initial-scale=1";
                title { (title) }
                link rel="stylesheet" href="/assets/app.css";
            }
            body data-page=(page) {
                // The builder keeps the scenario being built in the tab's
                // session storage: these links lose nothing.
                header {
                    a #home href="/" { "netfi" } " — " (title)
                    nav { a #nav-builder href="/" { "builder" } a #nav-runs href="/runs" { "runs" } }
                }
                main { (body) }
                script src=(script) {}
            }
        }
    }
}

fn shell(title: &str, page: &str, body: Markup) -> Markup {
    shell_with(title, page, "/assets/app.js", body)
}

/// The choices of a preset list, after `first`.
fn preset_options(first: Markup) -> Markup {
    html! {
        (first)
        @for p in crate::scenario::PRESET_NAMES { option value=(p) { (p) " — " (crate::scenario::preset_label(p).unwrap_or("")) } }
    }
}

/// `/`: build a scenario, preview it, run it.
pub async fn index() -> Markup {
    let catalogue = super::builder::catalogue();
    shell(
        "scenario builder",
        "builder",
        html! {
            script id="catalogue" type="application/json" { (PreEscaped(catalogue.to_string().replace("</", "<\\/"))) }
            section id="builder" {
                h2 { "Scenario" }
                label { "name " input id="scenario-name" value="my scenario"; }
                label { " seed " input id="scenario-seed" type="number" min="0" value="1"; }
                p id="timeline-note" class="note" hidden {}
                div id="stages" {}
                div class="add" {
                    select id="add-model" {}
                    button id="add-model-btn" { "add model" }
                    select id="add-preset" {}
                    button id="add-preset-btn" { "add preset" }
                    select id="add-target" {}
                    input id="add-target-value" type="number" step="any";
                    button id="add-target-btn" { "add target" }
                }
            }
            section id="file" {
                h2 { "TOML" }
                textarea id="toml" rows="16" spellcheck="false" {}
                div {
                    button id="apply-text" { "use this text" }
                    label class="file" { "load " input id="load" type="file" accept=".toml"; }
                    button id="save" { "save" }
                    button id="new-scenario" { "start anew" }
                }
                pre id="toml-error" class="error" {}
            }
            section id="preview-box" {
                h2 { "What it realizes (simulated time)" }
                label { "frames " input id="preview-frames" type="number" value="100000" min="1000" max="5000000"; }
                label { " at " input id="preview-rate" type="number" value="1000" min="1"; " Hz " }
                button id="preview-btn" { "preview" }
                label { input id="preview-auto" type="checkbox" checked; " again as the scenario changes" }
                div id="preview" {}
            }
            section id="run-box" {
                h2 { "Run" }
                div class="run-form" {
                    label { "duration " input id="duration" value="10s"; }
                    label { "rate (Hz) " input id="run-rate" type="number" min="0.001" step="any" value="1000"; }
                    label { "feedback path " select id="run-return" { (preset_options(html! {
                        option value="" { "Normal (nothing injected)" } option value="none" { "none: no feedback path" }
                    })) } }
                    label { "video (Mbit/s) " input id="run-video" type="number" min="0" step="any" placeholder="none"; }
                    label { "video through " select id="run-video-scenario" { (preset_options(html! { option value="" { "Normal (nothing injected)" } })) } }
                    label { "replay capture " input id="run-capture" placeholder="path on this host; empty: synthetic motion" size="40"; }
                    label { input id="run-isolate" type="checkbox" checked; " clear the emulator's core for the run (isolation)" }
                }
                button id="run-btn" { "run" }
                pre id="run-error" class="error" {}
            }
        },
    )
}

/// A run's state as a class and words.
fn state_cell(s: &super::runs::Status) -> Markup {
    html! { span class={ "state " (s.state) } { (s.state) } }
}

/// `/runs`: every run this server started, and those earlier servers left
/// in its output directory.
pub async fn runs(State(ui): State<Arc<Ui>>) -> Markup {
    let list = ui.runs.list(&ui.opts.out_dir);
    shell(
        "runs",
        "runs",
        html! {
            h2 { "Runs" }
            @if list.is_empty() {
                p id="no-runs" class="none" { "No run yet: build a scenario and run it." }
            } @else {
                table id="run-list" class="figures" {
                    tr { th { "run" } th { "scenario" } th { "started" } th { "duration (s)" } th { "state" } th { "" } th { "" } }
                    @for s in &list {
                        tr class="run" data-id=(s.id) data-state=(s.state) {
                            td { a href={ "/runs/" (s.id) } { (s.id) } }
                            td { (s.scenario) }
                            td class="started" data-unix=(s.started_unix_s) { (s.started_unix_s) }
                            td { (format!("{:.1}", if s.state == "running" { s.elapsed_s } else { s.duration_s })) }
                            td { (state_cell(s)) }
                            td class="said" { (s.state_said) }
                            td { @if s.state != "running" { a href={ "/runs/" (s.id) "/report" } { "report" } } }
                        }
                    }
                }
            }
        },
    )
}

/// `/runs/{id}`: a run's state, live control, and its report once done.
pub async fn run(State(ui): State<Arc<Ui>>, Path(id): Path<String>) -> impl IntoResponse {
    let Some(status) = ui.runs.status(&ui.opts.out_dir, &id) else {
        return (axum::http::StatusCode::NOT_FOUND, shell("no such run", "missing", html! { p { "No run " (id) " here." } }));
    };
    let body = html! {
        h2 { "Run " span id="run-id" { (id) } }
        p { "scenario " b id="run-scenario" { (status.scenario) } " · " span id="run-state" class={ "state " (status.state) } { (status.state) }
            span id="run-elapsed" {} " · output " code { (status.out) } }
        p id="run-said" {}
        section id="control" {
            h3 { "Live control" }
            p id="control-note" class="note" {}
            div class="ctl-row" {
                label { "switch to " select id="switch-to" { (preset_options(html! {
                    option value="@built" id="switch-built" disabled { "the scenario being built" }
                })) } }
                label { " at " input id="switch-at" placeholder="now" size="12"
                    title="empty: now; 12.5s: that time from the run's first frame; +5s: that long from now"; }
                button id="switch-btn" { "switch" }
            }
            div class="ctl-row" {
                label { "go to phase " select id="phase-to" {} }
                label { " at " input id="phase-at" placeholder="now" size="12"; }
                button id="phase-btn" { "go" }
            }
            div class="ctl-row" {
                button id="pause-btn" { "pause faults" }
                button id="resume-btn" { "resume" }
                button id="stop-btn" { "stop run" }
            }
            p { "Now: " span id="ctl-now" { "-" } }
            pre id="ctl-error" class="error" {}
            h3 { "Events" }
            ul id="events" {}
        }
        section id="live" { h3 { "Live" } div id="live-table" {} div id="live-plot" {} }
        section id="done" hidden {
            h3 { "Result" }
            p { "realized loss over the whole run " b id="run-loss" {} }
            div id="run-phases" {}
            ul id="run-faults" class="error" {}
            a id="report-link" href={ "/runs/" (id) "/report" } { "the run's report" }
            pre id="run-stderr" {}
        }
    };
    (axum::http::StatusCode::OK, shell(&format!("run {id}"), "run", body))
}

pub async fn script() -> impl IntoResponse {
    ([(header::CONTENT_TYPE, "text/javascript; charset=utf-8")], APP_JS)
}

pub async fn style() -> impl IntoResponse {
    ([(header::CONTENT_TYPE, "text/css; charset=utf-8")], APP_CSS)
}
