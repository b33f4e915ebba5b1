use chladni::part::Part;
use chladni::plate::model::PlateModel;
use chladni::sim::{self, Body, FieldModel, Pose, SimParams};
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let part = Part::load(a[1].as_ref()).unwrap();
    let plate = PlateModel::load(a[2].as_ref()).unwrap();
    let k: usize = a[3].parse().unwrap();
    let body = Body::with_samples(&part, 160);
    let f = FieldModel::new(&plate.modes[k], &plate);
    let p = SimParams { speed: plate.modes[k].speed_mm_s, t_limit: 3600.0, run_to_limit: false };
    for th in (0..24).map(|i| i as f64 * 15.0) {
        let r = sim::run(
            &body,
            &f,
            p,
            Pose { x: a[4].parse().unwrap(), y: a[5].parse().unwrap(), theta: th.to_radians() },
        );
        println!(
            "{th}: settle {:.2} end {:.2} steps {} final {:.2} {:.2} {:.2}",
            r.settle_s,
            r.t_end,
            r.steps,
            r.pose.x,
            r.pose.y,
            r.pose.theta.to_degrees()
        );
    }
}
