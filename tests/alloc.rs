//! Zero allocations per frame in steady state: a counting global allocator
//! watches the injector (decide, queue, release) over many frames after a
//! warm-up. Its own binary, because the allocator is process-wide.

use netfi::injector::Injector;
use netfi::sample::FrameSample;
use netfi::scenario::{self, Scenario};

#[path = "common/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::{allocations, Counting};

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Runs `frames` frames at 1 kHz through the injector and returns the
/// allocations made during the last `measured` of them.
fn allocations_in_steady_state(scenario_text: &str, frames: u64, measured: u64) -> u64 {
    let spec = scenario::parse_str(scenario_text, "alloc.toml", "alloc").unwrap();
    let mut inj: Injector<FrameSample> = Injector::new(Scenario::new(&spec, 3).unwrap(), 1 << 16);
    let mut before = 0;
    let mut sample = FrameSample::ZERO;
    for i in 0..frames {
        if i == frames - measured {
            before = allocations();
        }
        let now = i * 1_000_000;
        while let Some(r) = inj.pop_due(now) {
            std::hint::black_box(r);
        }
        sample.console_index = i;
        std::hint::black_box(inj.ingress(now, sample));
    }
    allocations() - before
}

#[test]
fn the_injector_does_not_allocate_per_frame() {
    let pipelines = [
        ("PLM-2 → DLM-2", "[[stage]]\npreset = \"PLM-2\"\n[[stage]]\npreset = \"DLM-2\"\n"),
        ("every model", "[[stage]]\nmodel = \"bernoulli\"\np = 0.01\n[[stage]]\nmodel = \"markov4\"\np13 = 0.01\np31 = 0.3\n[[stage]]\nmodel = \"gilbert_elliott\"\np = 0.01\n[[stage]]\npreset = \"CLM-2\"\n[[stage]]\nmodel = \"delay\"\nmin_ms = 10\ndist = \"uniform\"\njitter_ms = 5\norder = \"fifo\"\n"),
        ("phases", "[[phase]]\npreset = \"DLM-3\"\n[[phase]]\nstart_s = 100\npreset = \"PLM-1\"\n"),
    ];
    for (name, text) in pipelines {
        // 300 s of frames; the last 200 s measured, well past the queue's fill-up.
        let n = allocations_in_steady_state(text, 300_000, 200_000);
        assert_eq!(n, 0, "{name}: {n} allocations in 200000 frames");
    }
}
