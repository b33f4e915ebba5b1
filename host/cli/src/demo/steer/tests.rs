use chladni_media::vision::{Levels, Unknown, Why};

use super::*;

fn located(x: f64, y: f64) -> Located {
    Located {
        part: "triangle".into(),
        x_mm: x,
        y_mm: y,
        theta_deg: 0.0,
        flipped: false,
        face_certain: true,
        score: 0.95,
        rms_px: 0.2,
        touching: false,
        kind: 0,
    }
}

fn cluster(x: f64, y: f64) -> Unknown {
    let part = Some("triangle".into());
    Unknown { why: Why::Cluster, part, count: Some(2), area_mm2: 600.0, x_mm: x, y_mm: y }
}

fn report(parts: Vec<Located>, unknown: Vec<Unknown>) -> Report {
    Report {
        parts,
        unknown,
        corners: [[0.0; 2]; 4],
        corners_found: true,
        pixel_mm: 0.3,
        parts_dark: true,
        levels: Levels { parts_dark: true, threshold: 0.5, contrast: 0.5 },
    }
}

#[test]
fn the_fed_part_is_the_one_nearest_the_planned_position_and_the_others_are_set_aside() {
    let r = report(
        vec![located(230.0, 148.0), located(68.0, 150.0), located(206.0, 42.0)],
        vec![cluster(150.0, 100.0), cluster(80.0, 160.0)],
    );
    let (fed, others) = fed_part(&r, Some([66.0, 148.7]));
    assert_eq!(fed.parts, [located(68.0, 150.0)]);
    assert_eq!(fed.unknown, [cluster(80.0, 160.0)], "a cluster near the position may hide it");
    assert_eq!(others, [located(230.0, 148.0), located(206.0, 42.0)]);

    // None near the planned position: nothing fed is seen, and every part is another.
    let (fed, others) = fed_part(&r, Some([150.0, 180.0]));
    assert!(fed.parts.is_empty() && fed.unknown.is_empty());
    assert_eq!(others.len(), 3);

    // A plan that fixes no position: every part is judged.
    let (fed, others) = fed_part(&r, None);
    assert_eq!((fed.parts.len(), fed.unknown.len(), others.len()), (3, 2, 0));
}

#[test]
fn the_learned_plate_is_compared_with_the_truth_mode_by_mode() {
    use chladni_core::model::plate_file::LearnedMode;
    let learned = |freq_hz: f64, speed_factor: f64, shift_mm: [f64; 2]| LearnedMode {
        freq_hz,
        speed_factor,
        shift_mm,
        ..LearnedMode::default()
    };
    let truth = |freq_hz: f64, speed_factor: f64, shift_mm: [f64; 2]| ModeTruth {
        freq_hz,
        name: String::new(),
        shift_mm,
        speed_mm_s: 20.0 * speed_factor,
        speed_factor: Some(speed_factor),
    };
    let table = LearnedTable {
        mode: vec![
            learned(100.0, 1.1, [3.0, 4.0]),
            learned(200.0, 0.5, [0.0, 0.0]),
            learned(300.0, 2.0, [1.0, 1.0]),
            learned(999.0, 9.0, [50.0, 50.0]),
        ],
        ..LearnedTable::default()
    };
    let modes = [
        truth(100.0, 1.0, [0.0, 0.0]),
        truth(200.0, 0.5, [0.0, 1.0]),
        truth(300.0, 2.5, [1.0, 1.0]),
    ];
    let a = against_truth(&table, &modes).unwrap();
    // Speeds off by 10 %, 0 %, 20 %; shifts by 5, 1, 0 mm; the 999 Hz mode has no truth.
    assert!((a.speed_off[0] - 0.1).abs() < 1e-12 && (a.speed_off[1] - 0.2).abs() < 1e-12);
    assert_eq!(a.shift_off_mm, [1.0, 5.0]);
    assert_eq!(against_truth(&LearnedTable::default(), &modes), None);
    assert_eq!(median_max(&mut [4.0, 1.0, 3.0, 2.0]), Some([2.5, 4.0]));
}
