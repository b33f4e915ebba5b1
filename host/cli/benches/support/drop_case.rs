//! What the bulk benches drop: a part, its plate and plan, and everything one drop of copies
//! needs (steps, field models, the body and its convex pieces), built once per case. Shared by
//! `bulk` and `rapier` (compiled into each through `#[path]`; the crate root has `mod
//! examples`).
#![allow(dead_code)]

use chladni_core::model::part::Part;
use chladni_core::model::plan_file::PlanFile;
use chladni_core::model::plate::PlateModel;
use chladni_core::motion::body::Body;
use chladni_core::motion::bulk::Drop;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::shape::Pieces;
use chladni_core::motion::steps::SimStep;
use chladni_core::motion::steps::plan_steps;

/// One case: a part, its plate and plan, and what a drop needs.
pub struct DropCase {
    pub name: &'static str,
    pub plate: PlateModel,
    pub plan: PlanFile,
    pub steps: Vec<SimStep>,
    pub fields: Vec<FieldModel>,
    pub body: Body,
    pub pieces: Pieces,
}

impl DropCase {
    pub fn new(name: &'static str, part: Part, plate: PlateModel, plan: PlanFile) -> DropCase {
        let steps = plan_steps(&plan, &plate).expect("the plan runs on its plate");
        let fields = plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
        let body = Body::new(&part);
        let pieces = Pieces::of(&body);
        DropCase { name, plate, plan, steps, fields, body, pieces }
    }

    /// The triangle through its example plan on the four-lines plate
    /// (examples/plans/triangle-four-lines.json).
    pub fn triangle_four_lines() -> DropCase {
        let path = crate::examples::root().join("examples/plans/triangle-four-lines.json");
        let text = std::fs::read_to_string(path).expect("example plan");
        let plan = PlanFile::parse(&text).expect("example plan");
        let part = crate::examples::part("triangle.json");
        let plate = crate::examples::plate("four-lines.toml");
        DropCase::new("triangle on four-lines", part, plate, plan)
    }

    /// A drop of the copies `b` (bodies) with their pieces `p`, no feed region.
    pub fn drop<'a>(&'a self, b: &'a [&'a Body], p: &'a [&'a Pieces]) -> Drop<'a> {
        Drop {
            bodies: b,
            pieces: p,
            plate: &self.plate,
            fields: &self.fields,
            steps: &self.steps,
            feed: None,
        }
    }
}
