//! `netfi ctl`: live control of a running emulator, and its telemetry.

use crate::cli::{CtlArgs, CtlCmd};
use anyhow::{bail, Context, Result};
use netfi::service::control::{Request, Response, State, Target};
use netfi::transport::ipc::control::{ControlClient, TelemetrySample, TelemetrySubscriber};
use netfi::transport::{IpcConfig, RunId};
use std::time::Duration;

/// How long a request waits for its answer: the emulator answers once its
/// loop has taken the command (within milliseconds), or after 2 s.
const ANSWER_WAIT: Duration = Duration::from_secs(5);

pub fn run(args: CtlArgs) -> Result<()> {
    let config = IpcConfig::new(RunId::new(&args.run_id)?);
    if let CtlCmd::Watch { count } = args.command {
        return watch(&config, count, args.json);
    }
    let request = match &args.command {
        CtlCmd::Show => Request::Show,
        CtlCmd::Pause => Request::Pause,
        CtlCmd::Resume => Request::Resume,
        CtlCmd::Switch { scenario, at } => {
            let target = target(scenario)?;
            let client = ControlClient::open(&config)?;
            let at_ms = at.as_deref().map(|t| at_ms(&client, t)).transpose()?;
            return answer(&client, &Request::Switch { scenario: target, at_ms }, args.json);
        }
        CtlCmd::Phase { phase, at } => {
            let client = ControlClient::open(&config)?;
            let at_ms = at.as_deref().map(|t| at_ms(&client, t)).transpose()?;
            return answer(&client, &Request::Phase { phase: phase.clone(), at_ms }, args.json);
        }
        CtlCmd::Watch { .. } => unreachable!("handled above"),
    };
    let client = ControlClient::open(&config)?;
    answer(&client, &request, args.json)
}

fn ask(client: &ControlClient, request: &Request) -> Result<Response> {
    let bytes = client.request(&serde_json::to_vec(request)?, ANSWER_WAIT)?;
    serde_json::from_slice(&bytes).context("reading the emulator's answer")
}

/// Sends `request` and prints the answer; an error answer is an error.
fn answer(client: &ControlClient, request: &Request, json: bool) -> Result<()> {
    let r = ask(client, request)?;
    if !r.ok {
        bail!("{}", r.message);
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&r)?);
        return Ok(());
    }
    if !r.message.is_empty() {
        println!("{}", r.message);
    }
    if let Some(s) = &r.state {
        print!("{}", show(s));
    }
    Ok(())
}

fn show(s: &State) -> String {
    let mut out = format!(
        "t          {:.3} s from the first frame{} ({} frames entered)\nscenario   {} (phase {}{}), run phase {}\nfaults     {}\nqueue      {}\n",
        s.t_s,
        if s.started { "" } else { " (no frame yet)" },
        s.frames_entered,
        s.scenario,
        s.scenario_phase,
        s.phase_name.as_deref().map(|n| format!(", {n}")).unwrap_or_default(),
        s.phase,
        if s.paused { "PAUSED: every frame passes untouched" } else { "on" },
        s.queue_order,
    );
    for (t, scenario, phase) in &s.upcoming {
        out += &format!("next       at {t:.3} s: {scenario} (phase {phase})\n");
    }
    out
}

/// What `netfi ctl switch` names, as the emulator reads it: a preset, a
/// target stage (`loss=30%`, `delay_ms_mean=250`, `outage=10%`), or a
/// scenario file (its text is sent; the emulator reads no file).
fn target(arg: &str) -> Result<Target> {
    if netfi::scenario::canonical_name(arg).is_some() {
        return Ok(Target::Preset(arg.to_string()));
    }
    let path = std::path::Path::new(arg);
    if path.is_file() {
        let text = netfi::load::open_regular(path)
            .and_then(std::io::read_to_string)
            .with_context(|| format!("reading {}", path.display()))?;
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        return Ok(Target::Toml { text, origin: arg.to_string(), name });
    }
    if let Some((key, value)) = arg.split_once('=') {
        let value = value.trim();
        let literal = if value.parse::<f64>().is_ok() { value.to_string() } else { toml::Value::String(value.to_string()).to_string() };
        return Ok(Target::Toml { text: format!("[[stage]]\n{} = {literal}\n", key.trim()), origin: arg.to_string(), name: arg.to_string() });
    }
    bail!(
        "{arg}: neither a scenario file, a preset (presets: {}) nor a target (`loss=30%`, `delay_ms_mean=250`, `outage=10%`)",
        netfi::scenario::PRESET_NAMES.join(", ")
    )
}

/// `--at`: a time from the run's first frame (`12.5s`, `250ms`, a number of
/// ms), or `+` and a time from now.
fn at_ms(client: &ControlClient, text: &str) -> Result<f64> {
    let (relative, t) = match text.trim().strip_prefix('+') {
        Some(rest) => (true, rest),
        None => (false, text.trim()),
    };
    let ms = parse_ms(t).with_context(|| format!("--at {text}: give a time such as 12.5s, 250ms or 1500 (ms), or +5s from now"))?;
    if !relative {
        return Ok(ms);
    }
    let now = ask(client, &Request::Show)?.state.map_or(0.0, |s| s.t_s * 1e3);
    Ok(now + ms)
}

fn parse_ms(t: &str) -> Result<f64> {
    netfi::model::parse_duration(t, netfi::model::TimeUnit::Ms).map_err(anyhow::Error::msg)
}

/// `netfi ctl watch`: the telemetry as a live table, until the run ends,
/// `count` intervals were printed, or Ctrl-C.
fn watch(config: &IpcConfig, count: Option<u64>, json: bool) -> Result<()> {
    let sub = TelemetrySubscriber::open(config)?;
    if !json {
        println!("{:>8} {:>5} {:>7} {:>7} {:>9} {:>7} {:>10} {:>10} {:>10} {:>10}", "t_s", "phase", "entered", "dropped", "delivered", "loss", "delay p50", "delay p99", "late p50", "late p99.9");
    }
    let (mut printed, mut gone_since) = (0u64, None::<std::time::Instant>);
    loop {
        while let Some(s) = sub.recv() {
            println!("{}", if json { json_line(&s) } else { row(&s) });
            printed += 1;
            if count.is_some_and(|c| printed >= c) {
                return Ok(());
            }
        }
        if sub.termination_requested() {
            return Ok(());
        }
        // The run has ended once its emulator stops publishing.
        match (sub.publisher_alive(), gone_since) {
            (true, _) => gone_since = None,
            (false, None) => gone_since = Some(std::time::Instant::now()),
            (false, Some(t)) if t.elapsed() > Duration::from_secs(1) => {
                eprintln!("the run's emulator has stopped publishing");
                return Ok(());
            }
            _ => {}
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn row(s: &TelemetrySample) -> String {
    let ms = |ns: u64| format!("{:.3} ms", ns as f64 / 1e6);
    let us = |ns: u64| format!("{:.1} µs", ns as f64 / 1e3);
    let loss = if s.loss_rate.is_nan() { "-".to_string() } else { format!("{:.1}%", s.loss_rate * 100.0) };
    let paused = if s.flags & TelemetrySample::FLAG_PAUSED != 0 { " paused" } else { "" };
    format!(
        "{:>8.1} {:>5} {:>7} {:>7} {:>9} {:>7} {:>10} {:>10} {:>10} {:>10}{paused}",
        s.start_ns as f64 / 1e9,
        s.phase,
        s.entered,
        s.dropped,
        s.delivered,
        loss,
        ms(s.injected_ns[0]),
        ms(s.injected_ns[2]),
        us(s.lateness_ns[0]),
        us(s.lateness_ns[2]),
    )
}

fn json_line(s: &TelemetrySample) -> String {
    serde_json::json!({
        "seq": s.seq, "start_ns": s.start_ns, "length_ns": s.length_ns, "phase": s.phase,
        "paused": s.flags & TelemetrySample::FLAG_PAUSED != 0,
        "entered": s.entered, "delivered": s.delivered, "dropped": s.dropped,
        "loss_rate": if s.loss_rate.is_nan() { None } else { Some(s.loss_rate) },
        "injected_ns": {"p50": s.injected_ns[0], "p90": s.injected_ns[1], "p99": s.injected_ns[2], "max": s.injected_ns[3]},
        "lateness_ns": {"p50": s.lateness_ns[0], "p99": s.lateness_ns[1], "p999": s.lateness_ns[2], "max": s.lateness_ns[3]},
    })
    .to_string()
}
