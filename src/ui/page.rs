//! The pages: the scenario builder (`/`) and a run's page (`/runs/{id}`).
//! Their script and style are compiled in ([`script`], [`style`]).

use super::Ui;
use axum::extract::{Path, State};
use axum::http::header;
use axum::response::IntoResponse;
use maud::{html, Markup, PreEscaped, DOCTYPE};
use std::sync::Arc;

const APP_JS: &str = include_str!("assets/app.js");
const APP_CSS: &str = include_str!("assets/app.css");

fn shell(title: &str, page: &str, body: Markup) -> Markup {
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
                header { a href="/" { "netfi" } " — " (title) }
                main { (body) }
                script src="/assets/app.js" {}
            }
        }
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
                }
                pre id="toml-error" class="error" {}
            }
            section id="preview-box" {
                h2 { "What it realizes (simulated time)" }
                label { "frames " input id="preview-frames" type="number" value="100000" min="1000" max="5000000"; }
                label { " at " input id="preview-rate" type="number" value="1000" min="1"; " Hz " }
                button id="preview-btn" { "preview" }
                div id="preview" {}
            }
            section id="run-box" {
                h2 { "Run" }
                label { "duration " input id="duration" value="10s"; }
                button id="run-btn" { "run" }
                pre id="run-error" class="error" {}
            }
        },
    )
}

/// `/runs/{id}`: a run's state, live control, and its report once done.
pub async fn run(State(ui): State<Arc<Ui>>, Path(id): Path<String>) -> impl IntoResponse {
    let Some(status) = ui.runs.status(&id) else {
        return (axum::http::StatusCode::NOT_FOUND, shell("no such run", "missing", html! { p { "No run " (id) " here." } }));
    };
    let presets = crate::scenario::PRESET_NAMES;
    let body = html! {
        h2 { "Run " span id="run-id" { (id) } }
        p { "scenario " b id="run-scenario" { (status.scenario) } " · " span id="run-state" { (status.state) } " · "
            span id="run-elapsed" {} }
        section id="control" {
            h3 { "Live control" }
            select id="switch-to" { @for p in presets { option value=(p) { (p) } } }
            button id="switch-btn" { "switch now" }
            button id="pause-btn" { "pause faults" }
            button id="resume-btn" { "resume" }
            button id="stop-btn" { "stop run" }
            pre id="ctl-error" class="error" {}
            h3 { "Events" }
            ul id="events" {}
        }
        section id="live" { h3 { "Live" } div id="live-table" {} div id="live-plot" {} }
        section id="done" hidden {
            h3 { "Result" }
            p { "realized loss " b id="run-loss" {} }
            a id="report-link" href={ "/runs/" (id) "/report" } { "report" }
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
