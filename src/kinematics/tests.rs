use super::*;
use crate::frame::{SURGEON_DISENGAGED, SURGEON_ENGAGED};

const MS: u64 = 1_000_000;

fn frame(sequence: u32, inc0: [i32; 3], inc1: [i32; 3], surgeon_mode: i32) -> ItpFrame {
    ItpFrame {
        sequence,
        delx: [inc0[0], inc1[0]],
        dely: [inc0[1], inc1[1]],
        delz: [inc0[2], inc1[2]],
        qw: [1.0, 1.0],
        grasp: [sequence as i32 * 10, -(sequence as i32)],
        surgeon_mode,
        ..ItpFrame::default()
    }
    .with_checksum()
}

fn kin() -> Kinematics {
    Kinematics::new(KinematicsConfig::default()).unwrap()
}

#[test]
fn bad_config_is_rejected() {
    let c = KinematicsConfig { stall_threshold_ns: 0, ..KinematicsConfig::default() };
    assert_eq!(Kinematics::new(c).unwrap_err(), KinematicsConfigError::StallThresholdZero);
    for unit_mm in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let c = KinematicsConfig { unit_mm, ..KinematicsConfig::default() };
        assert!(matches!(Integrator::new(c), Err(KinematicsConfigError::UnitNotPositive(_))));
    }
}

#[test]
fn motion_length_and_pose() {
    let mut i = Integrator::new(KinematicsConfig::default()).unwrap();
    assert!(i.push(0, &frame(1, [3, 4, 0], [0, 0, -2], SURGEON_ENGAGED)));
    assert!(i.push(MS, &frame(2, [0, 0, 12], [1, 2, 2], SURGEON_ENGAGED)));
    let r = i.report();
    assert_eq!(r.length_units, [5.0 + 12.0, 2.0 + 3.0]);
    assert_eq!(r.length_mm, [0.17, 0.05]);
    assert_eq!(r.poses[0].position, [3, 4, 12]);
    assert_eq!(r.poses[1].position, [1, 2, 0]);
    assert_eq!(r.poses[0].grasp, 20);
    assert_eq!(r.frames_applied, 2);
}

#[test]
fn released_clutch_freezes_the_arm_and_engage_edges_count() {
    let mut i = Integrator::new(KinematicsConfig::default()).unwrap();
    let modes = [1, 1, 0, 0, 1, 0, 1, 1];
    for (k, &m) in modes.iter().enumerate() {
        i.push(k as u64 * MS, &frame(k as u32, [1, 0, 0], [0, 1, 0], m));
    }
    let r = i.report();
    assert_eq!(r.clutch_activations, 2);
    assert_eq!(r.frames_applied, 5);
    assert_eq!(r.poses[0].position, [5, 0, 0]);
    assert_eq!(r.poses[1].position, [0, 5, 0]);
    assert_eq!(r.length_units, [5.0, 5.0]);
    // The grasp of the last applied frame (sequence 7).
    assert_eq!(r.poses[0].grasp, 70);

    // A stream that starts released counts its first engagement.
    let mut j = Integrator::new(KinematicsConfig::default()).unwrap();
    j.push(0, &frame(0, [0; 3], [0; 3], SURGEON_DISENGAGED));
    j.push(MS, &frame(1, [0; 3], [0; 3], SURGEON_ENGAGED));
    assert_eq!(j.report().clutch_activations, 1);
}

#[test]
fn rotation_increments_add_up() {
    let mut i = Integrator::new(KinematicsConfig::default()).unwrap();
    let mut f = frame(0, [0; 3], [0; 3], SURGEON_ENGAGED);
    f.qx = [1.0, 0.0];
    f.qz = [-2.0, 0.5];
    i.push(0, &f);
    i.push(MS, &f);
    assert_eq!(i.pose(0).rotation, [2.0, 0.0, -4.0]);
    assert_eq!(i.pose(1).rotation, [0.0, 0.0, 1.0]);
}

#[test]
fn stalls_are_gaps_over_the_threshold() {
    let mut i = Integrator::new(KinematicsConfig::default()).unwrap();
    let f = frame(0, [0; 3], [0; 3], SURGEON_ENGAGED);
    // Gaps: 5, 15, 1, 29, 10 (not over), then 3 back in time (ignored).
    for t_ms in [0, 5, 20, 21, 50, 60, 57] {
        i.push(t_ms * MS, &f);
    }
    assert_eq!(i.report().stalls, Stalls { count: 2, total_ns: 44 * MS, longest_ns: 29 * MS });
    // A trailing gap of 40 ms to the end of the run is a third.
    i.close(100 * MS);
    assert_eq!(i.report().stalls, Stalls { count: 3, total_ns: 84 * MS, longest_ns: 40 * MS });
}

#[test]
fn checksum_mismatches_are_counted_and_optionally_discarded() {
    let mut bad = frame(5, [7, 0, 0], [0; 3], SURGEON_ENGAGED);
    bad.checksum ^= 1;
    let mut apply = Integrator::new(KinematicsConfig::default()).unwrap();
    assert!(apply.push(0, &bad));
    assert_eq!(apply.report().checksum_mismatches, 1);
    assert_eq!(apply.pose(0).position, [7, 0, 0]);

    let config = KinematicsConfig { checksum_policy: ChecksumPolicy::Discard, ..KinematicsConfig::default() };
    let mut discard = Integrator::new(config).unwrap();
    assert!(!discard.push(0, &bad));
    let r = discard.report();
    assert_eq!((r.checksum_mismatches, r.frames_discarded, r.frames_applied), (1, 1, 0));
    assert_eq!(r.poses[0].position, [0, 0, 0]);
}

#[test]
fn one_lost_increment_is_exactly_the_divergence() {
    // Lockstep: the robot receives every frame but the third, whose arm-0
    // increment is (3, 4, 0): a divergence of exactly 5 units = 0.05 mm.
    let mut k = kin();
    for s in 0..10u32 {
        let inc0 = if s == 2 { [3, 4, 0] } else { [1, -1, 2] };
        let f = frame(s, inc0, [2, 2, 1], SURGEON_ENGAGED);
        let t = s as u64 * 2 * MS;
        k.console(t, &f);
        if s != 2 {
            k.robot(t + MS, &f);
        }
    }
    k.close(20 * MS);
    let r = k.report();
    assert_eq!(r.divergence[0].final_units, 5.0);
    assert_eq!(r.divergence[0].max_units, 5.0);
    assert!((r.divergence[0].final_mm - 0.05).abs() < 1e-12);
    assert_eq!(r.divergence[1].final_units, 3.0);
    assert_eq!(r.divergence[1].max_units, 3.0);
    // The robot's grasp follows the last frame, which arrived.
    assert_eq!(r.divergence[0].grasp_final, 0);
    assert_eq!(r.console.frames, 10);
    assert_eq!(r.robot.frames, 9);
    // 2·sqrt(6)·8 + ... on the console side; the robot lacks 5 and 3.
    assert!((r.console.length_units[0] - r.robot.length_units[0] - 5.0).abs() < 1e-9);
    assert!((r.console.length_units[1] - r.robot.length_units[1] - 3.0).abs() < 1e-9);
    // The lost frame leaves a 4 ms gap on the robot side: under 10 ms.
    assert_eq!(r.robot.stalls.count, 0);
}

#[test]
fn lost_increment_during_released_clutch_costs_nothing() {
    let mut k = kin();
    let moving = frame(0, [100, 0, 0], [0; 3], SURGEON_DISENGAGED);
    k.console(0, &moving);
    let r = k.report();
    assert_eq!(r.divergence[0].final_units, 0.0);
    assert_eq!(r.console.poses[0].position, [0, 0, 0]);
}

#[test]
fn delay_shows_as_lag_then_vanishes() {
    // Every frame arrives 3 frames late: while they are in flight the
    // robot trails by 3 increments of length 2; at the end it has caught
    // up.
    let mut k = kin();
    let f = |s| frame(s, [2, 0, 0], [0; 3], SURGEON_ENGAGED);
    for s in 0..10u32 {
        k.console(s as u64 * MS, &f(s));
        if s >= 3 {
            k.robot(s as u64 * MS, &f(s - 3));
        }
    }
    for s in 7..10u32 {
        k.robot((10 + s as u64) * MS, &f(s));
    }
    let r = k.report();
    // After the robot takes frame s−3 the console has sent s+1 frames.
    assert_eq!(r.divergence[0].max_units, 6.0);
    assert_eq!(r.divergence[0].final_units, 0.0);
}
