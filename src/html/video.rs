//! The page's video section (runs with `--video-mbps`): frames whole,
//! damaged and lost, the delay's percentiles and the freezes.

use crate::service::report::RunReport;
use maud::{html, Markup};

/// The section; a line saying so for a run without video.
pub fn section(r: &RunReport) -> Markup {
    let Some(v) = &r.channels.video else {
        return html! { section #video { h2 { "Video" } p #no-video.none { "no video in this run" } } };
    };
    let f = &v.frames;
    let ms = |ns: u64| format!("{:.2}", ns as f64 / 1e6);
    let opt_ms = |x: Option<f64>| x.map_or("-".to_string(), |x| format!("{x:.1}"));
    html! {
        section #video {
            h2 { "Video: robot → console through " (v.scenario) }
            @if let Some(c) = &v.camera {
                p { (format!("Camera: {:.0} Hz, {:.2} Mbit/s, group of {} (key frame {} B, delta {} B), {} frames sent.",
                    c.frame_hz, c.bit_rate_bit_s / 1e6, c.gop_frames, c.key_bytes, c.delta_bytes, c.frames_sent)) }
            }
            table #video-frames {
                tr { th { "through the emulator" } th { "whole" } th { "damaged" } th { "lost" } th { "held at end" } }
                tr { td { (f.sent) } td #video-whole { (f.whole) } td #video-damaged { (f.damaged) } td #video-lost { (f.lost) } td { (v.held_at_end) } }
            }
            @if let Some(d) = &v.delay_ns {
                table #video-delay {
                    tr { th { "delay, camera → console (ms)" } th { "p50" } th { "p90" } th { "p99" } th { "max" } }
                    tr { td { (d.count) " whole frames" } td { (ms(d.p50)) } td { (ms(d.p90)) } td { (ms(d.p99)) } td { (ms(d.max)) } }
                }
            } @else {
                p.none { "no whole frame received" }
            }
            p {
                "Freezes (gaps over " (opt_ms(v.freeze_threshold_ms)) " ms between displayed frames): "
                span #video-freezes { (v.freezes.map_or("-".to_string(), |n| n.to_string())) }
                ", total " (opt_ms(v.freeze_total_ms)) " ms, longest " (opt_ms(v.freeze_longest_ms)) " ms. Accounting: "
                @if v.balanced { "balanced" } @else { span.fault { "NOT balanced" } }
                "."
            }
        }
    }
}
