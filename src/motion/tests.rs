use super::*;
use crate::kinematics::{Integrator, KinematicsConfig};

#[test]
fn bad_parameters_are_rejected() {
    let good = MotionParams::peg_transfer(517.0);
    assert_eq!(good.validate(), Ok(()));
    let cases: [(&str, MotionParams); 6] = [
        ("rate_hz", MotionParams { rate_hz: 0.0, ..good.clone() }),
        ("rate_hz", MotionParams { rate_hz: f64::NAN, ..good.clone() }),
        ("move_units", MotionParams { move_units: [10.0, 5.0], ..good.clone() }),
        ("workspace_units[1]", MotionParams { workspace_units: [1.0, -1.0, 1.0], ..good.clone() }),
        ("grasp_closed", MotionParams { grasp_closed: [5, 1], ..good.clone() }),
        ("clutch_release_ms", MotionParams { clutch_release_ms: [0.0, 10.0], ..good.clone() }),
    ];
    for (field, params) in cases {
        let err = MotionGenerator::new(params, 1).unwrap_err();
        assert_eq!(err.field, field, "{err}");
    }
}

#[test]
fn same_seed_same_frames() {
    let a: Vec<_> = MotionGenerator::new(MotionParams::default(), 7).unwrap().take(20_000).collect();
    let b: Vec<_> = MotionGenerator::new(MotionParams::default(), 7).unwrap().take(20_000).collect();
    let c: Vec<_> = MotionGenerator::new(MotionParams::default(), 8).unwrap().take(20_000).collect();
    assert_eq!(a, b);
    assert_ne!(a, c);
}

/// FNV-1a over the wire bytes of the first `n` frames.
fn digest(g: &mut MotionGenerator, n: usize) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for _ in 0..n {
        for b in g.next_frame().to_bytes() {
            h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

#[test]
fn value_stability() {
    // Pins the stream of a fixed seed: a change here changes every
    // recorded experiment that used the generator.
    let mut g = MotionGenerator::new(MotionParams::default(), 42).unwrap();
    assert_eq!(digest(&mut g, 50_000), 0xc1cb_67f5_f595_0afb);
}

#[test]
fn frames_are_well_formed() {
    let params = MotionParams { sequence_start: u32::MAX - 2, ..MotionParams::peg_transfer(517.0) };
    let mut released = 0;
    for (k, f) in MotionGenerator::new(params, 3).unwrap().take(100_000).enumerate() {
        assert_eq!(f.sequence, (u32::MAX - 2).wrapping_add(k as u32));
        assert!(f.has_valid_checksum());
        assert_eq!(f.qw, [1.0, 1.0]);
        assert_eq!(f.buttonstate, f.grasp);
        assert!(f.grasp.iter().all(|g| g % GRASP_STEP == 0));
        assert!(f.surgeon_mode == SURGEON_ENGAGED || f.surgeon_mode == SURGEON_DISENGAGED);
        if !f.clutch_engaged() {
            assert_eq!((f.delx, f.dely, f.delz), ([0; 2], [0; 2], [0; 2]));
            released += 1;
        }
    }
    assert!(released > 0, "the clutch was never released: its frames were not checked");
}

#[test]
fn increments_sum_to_the_continuous_pose() {
    // The carried remainder keeps the integrated pose within half a unit
    // of the continuous one.
    let mut g = MotionGenerator::new(MotionParams::peg_transfer(517.0), 11).unwrap();
    let mut sum = [[0i64; 3]; ARMS];
    for _ in 0..200_000 {
        let f = g.next_frame();
        for (arm, s) in sum.iter_mut().enumerate() {
            for (k, d) in f.increment(arm).into_iter().enumerate() {
                s[k] += d as i64;
            }
        }
    }
    for (arm, s) in sum.iter().enumerate() {
        for (k, &v) in s.iter().enumerate() {
            assert!((v as f64 - g.arms[arm].position[k]).abs() <= 0.5);
            assert!(v.unsigned_abs() as f64 <= g.params.workspace_units[k] + 0.5);
        }
    }
}

/// Mean motion per second, per arm, and the clutch-released share of a
/// generated run of `seconds` at `rate_hz`.
fn run_stats(rate_hz: f64, seconds: f64, seed: u64) -> ([f64; ARMS], f64) {
    let mut g = MotionGenerator::new(MotionParams::peg_transfer(rate_hz), seed).unwrap();
    let mut i = Integrator::new(KinematicsConfig::default()).unwrap();
    let frames = (seconds * rate_hz) as u64;
    let mut released = 0u64;
    for k in 0..frames {
        let f = g.next_frame();
        released += !f.clutch_engaged() as u64;
        i.push(g.frame_time_ns(k), &f);
    }
    let duration_s = (frames - 1) as f64 / rate_hz;
    (i.report().length_units.map(|l| l / duration_s), released as f64 / frames as f64)
}

// Measured on the shipped capture (80.3 s): motion of 975.7 and 981.2
// units/s for arms 0 and 1, and 1,058 of 41,508 frames (2.55 %) with the
// clutch released. The integration tests measure them again from the file.
const CAPTURE_UNITS_PER_S: [f64; 2] = [975.7, 981.2];
const CAPTURE_RELEASED_FRACTION: f64 = 1058.0 / 41508.0;

#[test]
fn statistics_resemble_the_capture() {
    // One hour of generated motion holds about 1,000 moves per arm and 100
    // clutch releases. Over seeds 1..=20 at 517 Hz the per-arm rate came
    // out at 986 and 991 units/s with a s.d. of 10 (1.1 %) and the
    // released share at 2.57 % with a s.d. of 0.11 points (4.3 %). At
    // 1 kHz the rate reads about 3 % higher: rounding each frame's
    // increment to whole units adds more path when steps are smaller. The
    // tolerances, ±10 % and ±20 %, leave those offsets plus over 4σ of
    // seed-to-seed spread.
    for (rate_hz, seed) in [(517.0, 1), (1000.0, 2)] {
        let (units_per_s, released) = run_stats(rate_hz, 3600.0, seed);
        for arm in 0..ARMS {
            let rel = units_per_s[arm] / CAPTURE_UNITS_PER_S[arm] - 1.0;
            assert!(rel.abs() < 0.10, "{rate_hz} Hz arm {arm}: {:.1} units/s", units_per_s[arm]);
        }
        let rel = released / CAPTURE_RELEASED_FRACTION - 1.0;
        assert!(rel.abs() < 0.20, "{rate_hz} Hz: released fraction {released:.4}");
    }
}
