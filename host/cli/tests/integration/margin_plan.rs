//! Margins from evidence (docs/plan.md, "Margins from evidence"): a plate whose grid modes'
//! boundaries do not move when their grids are resampled plans with the evidence margin where
//! the fixed 3° refuses, and the plan holds in Monte Carlo; `plan --json` names each step's
//! margin and its source, and a refusal names the margin it applied.

use chladni_core::motion::body::Body;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::montecarlo::{self, Setup};
use chladni_core::planner::mode_margin::{MIN_MARGIN_DEG, MarginSource};
use chladni_core::planner::{self, PlanOptions, Problem};

use crate::support;
use support::cli::{chladni, ex, json, ok_json};
use support::examples::{line_grid_plate, part};

#[test]
fn plan_json_names_each_steps_margin_and_its_source() {
    let (tri, four) = (ex("parts/triangle.json"), ex("plates/four-lines.toml"));
    // Straight nodes have no grid to resample: the default 3°, said so.
    let auto = ok_json(&chladni(&["plan", &tri, "--plate", &four, "--json"]));
    let m = auto["margins"].as_array().unwrap();
    assert_eq!(m.len(), auto["steps"].as_array().unwrap().len());
    assert_eq!(m[0]["source"], "default");
    assert_eq!(m[0]["deg"], 3.0);
    assert_eq!(m[0]["step"], 1);
    // A number given overrides every mode.
    let given =
        ok_json(&chladni(&["plan", &tri, "--plate", &four, "--margin-deg", "2.5", "--json"]));
    assert!(
        given["margins"]
            .as_array()
            .unwrap()
            .iter()
            .all(|s| s["source"] == "given" && s["deg"] == 2.5)
    );
    // Neither a number in range nor `auto`: a usage error naming both.
    let bad = chladni(&["plan", &tri, "--plate", &four, "--margin-deg", "lots"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("in [0, 45) or auto"), "{bad:?}");
    // The trapezoid's refusal names the margin and where it came from.
    let trap = chladni(&["plan", &ex("parts/trapezoid.json"), "--plate", &four, "--json"]);
    assert_eq!(trap.status.code(), Some(1));
    let err = json(&trap).to_string();
    assert!(err.contains("--margin-deg 3°, the default: the map has no grid to resample"), "{err}");
}

/// The plate of the plan test: two straight grid nodes 90° apart (`line_grid_plate`,
/// right-hand gain 2). Under each the triangle has two rests (at 7°: 34.04° and 201.04°,
/// boundaries 118° and 298° on the 10° lattice of 36 starts; at 97°: 124.03° and 291.05°,
/// boundaries 28° and 208°): either mode's rests lie 6.0° and 7.0° from the other's boundaries
/// and in one of its basins, so the two steps orient the triangle when the margin plus the 5°
/// slack is below 6.0° and never when it is the fixed 3° + 5°.
const ANGLES: [f64; 2] = [7.0, 97.0];

#[test]
fn the_evidence_margin_plans_where_a_fixed_three_degrees_refuses_and_the_plan_holds() {
    let plate = line_grid_plate(&ANGLES, 2.0);
    let tri = part("triangle.json");
    // 36 start orientations per map (10° apart): the sampling slack is 5°. The maps are made
    // once; without their evidence they keep the fixed margin.
    let auto = PlanOptions { sim_starts: 36, ..Default::default() };
    let problem = Problem::new(&tri, &plate, &auto).unwrap();
    let mut without = problem.clone();
    without.maps.iter_mut().for_each(|m| m.evidence = None);
    let fixed = PlanOptions { margin_auto: false, ..auto };
    let err = without.search(&fixed).unwrap_err().to_string();
    assert!(err.contains("at least 8.00° (--margin-deg 3° plus 5.00°"), "{err}");
    // The linear fields' resampling moves no boundary: each mode keeps the 0.5° floor.
    let syn = planner::plan_with(&tri, &plate, &auto, &problem).unwrap();
    assert!(syn.steps.len() >= 2, "{:?}", syn.steps);
    for s in &syn.steps {
        assert_eq!(s.margin.deg, MIN_MARGIN_DEG, "{:?}", s.margin);
        assert!(
            matches!(s.margin.source, MarginSource::Resampled { spread_deg, .. } if spread_deg == 0.0),
            "{:?}",
            s.margin
        );
    }
    // The plan holds from random drops over the whole plate: the band is the table's
    // criterion (≥ 95 % within 5°), over 100 trials.
    let body = Body::new(&tri);
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
    let steps = syn.sim_steps();
    let setup = Setup { body: &body, plate: &plate, fields: &fields, steps: &steps, feed: None };
    let trials = montecarlo::run_trials(&setup, 100, 1, &chladni_core::progress::Silent);
    let stats = montecarlo::statistics(&trials, &syn.to_file(&plate, "t"), 5.0);
    let rate = stats.success_rate.unwrap();
    assert!(rate >= 0.95, "{rate}: misses from {:?}", stats.misses);
}
