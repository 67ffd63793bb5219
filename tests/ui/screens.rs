//! The experimenter's screens as a study uses them: a four-state loss model
//! built by hand through the matrix grid, realizing its loss; a run switched
//! live to the scenario being built at a chosen time, then stopped, reported
//! as stopped and balanced, and its report's figures per condition.

use super::*;

/// Types `value` into the input `id` as a person would (an `input` event).
fn type_into(tab: &Tab, id: &str, value: &str) {
    js(tab, &format!("(() => {{ const e = document.getElementById('{id}'); e.value = '{value}'; e.dispatchEvent(new Event('input')); }})()"));
}

fn number(tab: &Tab, code: &str) -> f64 {
    js(tab, code).as_f64().unwrap_or_else(|| panic!("`{code}` is not a number"))
}

#[test]
fn a_four_state_chain_built_through_the_grid_realizes_its_loss() {
    let Some(browser) = browser_or_skip() else { return };
    let server = Server::start();
    let tab = browser.new_tab().unwrap();
    tab.navigate_to(&server.url).unwrap().wait_until_navigated().unwrap();
    // The example stage is a two-state ge_lomax: Good and Bad.
    until(&tab, "document.querySelectorAll('#matrix-1 table.matrix tr').length === 3", 10);
    click(&tab, "#add-state-1");
    until(&tab, "!!document.getElementById('tm-1-2-2')", 5);
    click(&tab, "#add-state-1");
    until(&tab, "!!document.getElementById('tm-1-3-3')", 5);
    assert!(js(&tab, "document.getElementById('add-state-1').disabled").as_bool().unwrap(), "a fifth state is offered");
    let names = js(&tab, "Array.from(document.querySelectorAll('#matrix-1 input[id^=state-name]')).map(e => e.value).join('|')");
    assert_eq!(names, "Good|Bad|Intermediate 1|Intermediate 2");

    // Good → Intermediate 1 with 0.03: the row's others scale to keep it at 1.
    type_into(&tab, "tm-1-0-2", "0.03");
    // Bad → Intermediate 2 with 0.2, the stay probability taking the difference.
    js(&tab, "document.getElementById('rebalance-1').value = 'stay'; document.getElementById('rebalance-1').dispatchEvent(new Event('change'))");
    type_into(&tab, "tm-1-1-3", "0.2");
    for i in 0..4 {
        assert_eq!(text(&tab, &format!("row-sum-1-{i}")), "1.0000", "row {i}");
    }
    let cell = |i: usize, j: usize| number(&tab, &format!("Number(document.getElementById('tm-1-{i}-{j}').value)"));
    assert!((cell(0, 2) - 0.03).abs() < 1e-9 && (cell(0, 0) + cell(0, 1) - 0.97).abs() < 1e-6);
    assert!((cell(1, 1) - 0.7).abs() < 1e-6 && (cell(1, 0) - 0.1).abs() < 1e-6, "the stay probability took up 0.2");
    // The scenario text has the four rows, and the parser takes it (the
    // stage's own figures come back).
    let toml = js(&tab, "document.getElementById('toml').value").as_str().unwrap().to_string();
    assert!(toml.contains("transition = [[") && toml.matches('[').count() >= 5 + 2, "{toml}");

    // The chain: four states, each with its self-loop, every arrow with its
    // head, and the arrow Good → Intermediate 1 at the value typed.
    let drawn = "document.querySelector('#matrix-1 svg.chain')";
    assert_eq!(js(&tab, &format!("{drawn}.dataset.states")), "4");
    assert_eq!(number(&tab, &format!("{drawn}.querySelectorAll('circle.state').length")), 4.0);
    assert_eq!(number(&tab, &format!("{drawn}.querySelectorAll('path.edge.self').length")), 4.0);
    let headless = number(&tab, &format!("Array.from({drawn}.querySelectorAll('path.edge')).filter(e => !e.getAttribute('marker-end')).length"));
    assert_eq!(headless, 0.0, "an arrow without its head");
    let p02 = format!("Number({drawn}.querySelector('path.edge[data-from=\"0\"][data-to=\"2\"]')?.dataset.p)");
    assert!((number(&tab, &p02) - 0.03).abs() < 1e-9);
    // It follows the grid as the values move.
    type_into(&tab, "tm-1-0-2", "0.04");
    assert!((number(&tab, &p02) - 0.04).abs() < 1e-9, "the drawing did not follow the grid");

    // α and λ say what they realize, and follow their sliders.
    let said = text(&tab, "state-said-1-1");
    assert!(said.contains("on average"), "{said}");
    type_into(&tab, "alpha-1-1", "1.5");
    let said_after = text(&tab, "state-said-1-1");
    assert_ne!(said, said_after, "the words did not follow α");

    // What the stage realizes (50 000 simulated frames, seed 1) against
    // its model's long-run loss: the model within the realized 95%
    // interval, its half-width doubled (a false alarm once in 10^4).
    let realized = "document.getElementById('stage-loss-1')";
    until(&tab, &format!("{realized}?.dataset.model && Number(document.getElementById('alpha-1-1').value) === 1.5 && {realized}.dataset.value"), 60);
    std::thread::sleep(Duration::from_millis(1500));
    let loss = number(&tab, &format!("Number({realized}.dataset.value)"));
    let (lo, hi) = (number(&tab, &format!("Number({realized}.dataset.lo)")), number(&tab, &format!("Number({realized}.dataset.hi)")));
    let model = number(&tab, &format!("Number({realized}.dataset.model)"));
    let half = (hi - lo) / 2.0;
    assert!(model > 0.0 && (loss - model).abs() <= 2.0 * half, "realized {loss} [{lo}, {hi}], model {model}");
    assert!(svg_points(&tab, "plot-stage-bursts-1") > 3, "no burst lengths drawn");
    screenshot(&tab, "builder-grid.png");

    // The header's links lose nothing: the runs, then back to the builder.
    click(&tab, "#nav-runs");
    until(&tab, "location.pathname === '/runs' && document.readyState === 'complete'", 10);
    click(&tab, "#nav-builder");
    until(&tab, "!!document.getElementById('tm-1-3-3')", 10);
    assert!((cell(0, 2) - 0.04).abs() < 1e-9, "the builder lost the scenario");
}

#[test]
fn a_run_switched_to_the_built_scenario_then_stopped_is_reported_as_stopped_per_condition() {
    let Some(browser) = browser_or_skip() else { return };
    let _guard = machine::alone();
    let server = Server::start();
    let tab = browser.new_tab().unwrap();
    builder(&tab, &server);
    js(&tab, "document.getElementById('duration').value = '60s'");
    click(&tab, "#run-btn");
    until(&tab, "location.pathname.startsWith('/runs/') && document.getElementById('run-state')?.textContent === 'running'", 60);
    let id = text(&tab, "run-id");

    // Back to the builder (PLM-2 still there): build a Bernoulli loss of
    // 0.5 named `half`.
    click(&tab, "#nav-builder");
    until(&tab, "document.getElementById('toml')?.value.includes('PLM-2')", 10);
    js(&tab, "document.getElementById('preview-auto').checked = false");
    click(&tab, "#stages button.remove");
    js(&tab, "document.getElementById('add-model').value = 'bernoulli'");
    click(&tab, "#add-model-btn");
    js(&tab, "(() => { const e = document.querySelector('input[type=number][data-param=\"p\"]'); e.value = '0.5'; e.dispatchEvent(new Event('input')); })()");
    type_into(&tab, "scenario-name", "half");
    assert!(js(&tab, "document.getElementById('toml').value").as_str().unwrap().contains("p = 0.5"));

    // The runs: this one, running; its page.
    click(&tab, "#nav-runs");
    until(&tab, &format!("document.querySelector('tr.run[data-id=\"{id}\"]')?.dataset.state === 'running'"), 10);
    screenshot(&tab, "runs.png");
    click(&tab, &format!("tr.run[data-id=\"{id}\"] a"));
    until(&tab, "document.getElementById('run-state')?.textContent === 'running'", 10);
    // Switch to the scenario being built, 1 s from now.
    until(&tab, "!document.getElementById('switch-built').disabled", 5);
    js(&tab, "document.getElementById('switch-to').value = '@built'; document.getElementById('switch-at').value = '+1s'");
    click(&tab, "#switch-btn");
    let events = until(&tab, "document.getElementById('events').textContent", 20).as_str().unwrap().to_string();
    assert!(events.contains("half") && events.contains("will take effect"), "events: {events} {}", text(&tab, "ctl-error"));
    until(&tab, "document.getElementById('ctl-now').textContent.includes('half')", 20);
    screenshot(&tab, "run-switched.png");
    std::thread::sleep(Duration::from_secs(3));

    // Stopped: a normal end, every frame accounted for, nothing to steer.
    click(&tab, "#stop-btn");
    until(&tab, "!document.getElementById('done').hidden", 120);
    assert_eq!(text(&tab, "run-state"), "stopped", "{} {}", text(&tab, "run-said"), text(&tab, "run-faults"));
    assert!(text(&tab, "run-said").contains("every frame accounted for"), "{}", text(&tab, "run-said"));
    assert_eq!(number(&tab, "document.querySelectorAll('#run-faults li').length"), 0.0, "{}", text(&tab, "run-faults"));
    assert!(js(&tab, "['switch-btn', 'pause-btn', 'stop-btn', 'phase-btn'].every(b => document.getElementById(b).disabled)").as_bool().unwrap());
    let s = server.run_status(&id).unwrap();
    let r = &s["report"];
    assert_eq!((r["stopped"].as_bool(), r["frames"]["balanced"].as_bool()), (Some(true), Some(true)), "{r}");
    // The page's run has its feedback path (Normal, unless one is chosen).
    assert_eq!(r["feedback"]["balanced"].as_bool(), Some(true), "{}", r["feedback"]);
    let (status, body) = server.post_as_the_page(&format!("/api/runs/{id}/ctl"), r#"{"cmd": "pause"}"#);
    assert_eq!(status, 409, "{body}");

    // Each condition apart: the PLM-2 stage (0.3 in the long run), then `half`, each
    // with its interval (half-width doubled, as above).
    let phases = r["phases"].as_array().cloned().unwrap_or_default();
    assert_eq!(phases.len(), 2, "{phases:?}");
    for (p, (name, model)) in phases.iter().zip([("my scenario", 0.3), ("half", 0.5)]) {
        let (loss, ci) = (p["loss_rate"].as_f64().unwrap(), [p["loss_rate_ci95"][0].as_f64().unwrap(), p["loss_rate_ci95"][1].as_f64().unwrap()]);
        assert_eq!(p["scenario"], name);
        assert!((loss - model).abs() <= ci[1] - ci[0] + 1e-9, "{name}: {loss} {ci:?}, model {model}");
    }
    assert_eq!(number(&tab, "document.querySelectorAll('#run-phase-table tr.phase').length"), 2.0);
    screenshot(&tab, "run-stopped.png");

    // The report page: each condition's row, the switch on the time plots.
    click(&tab, "#report-link");
    until(&tab, "!!document.getElementById('phase-table')", 60);
    assert_eq!(number(&tab, "document.querySelectorAll('#phase-table tr.phase').length"), 2.0);
    let conditions = js(&tab, "Array.from(document.querySelectorAll('#phase-table td.condition')).map(e => e.textContent).join('|')");
    assert!(conditions.as_str().unwrap().contains("half"), "{conditions}");
    let marked = js(&tab, "Array.from(document.querySelectorAll('svg[id^=plot-]')).filter(s => s.textContent.includes('half')).length");
    assert!(marked.as_f64().unwrap() >= 1.0, "no time plot marks the switch");
    assert!(text(&tab, "ended").to_lowercase().contains("stopped on request"), "the report does not say the run was stopped");
    screenshot(&tab, "report-switched.png");
}
