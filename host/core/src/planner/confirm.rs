//! The dynamic confirmation of a straight-node transition: the simulated approach from
//! either side of the node must end where the map predicts.

use crate::model::angle::cdist;
use crate::model::plate::{Mode, PlateModel};
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::field::FieldModel;

/// Does the simulation take orientation `u` to `v` (mod `period`, within 1°) under a straight
/// node, approaching from either side, from beyond the part's radius and from half-way across?
pub fn confirm(body: &Body, mode: &Mode, plate: &PlateModel, u: f64, v: f64, period: f64) -> bool {
    confirm_any(body, mode, plate, u, &[v], period)
}

/// [`confirm`] for several possible images: every approach must end within 1° of one of them.
pub(crate) fn confirm_any(
    body: &Body,
    mode: &Mode,
    plate: &PlateModel,
    u: f64,
    images: &[f64],
    period: f64,
) -> bool {
    let field = FieldModel::new(mode, plate);
    let FieldModel::Line { xhat, c, .. } = field else { return true };
    let ctr = plate.center();
    let xi0 = xhat[0] * ctr[0] + xhat[1] * ctr[1] - c;
    let base = [ctr[0] - xi0 * xhat[0], ctr[1] - xi0 * xhat[1]];
    let p = super::settle::settle_params(mode, plate);
    let r = body.radius;
    [-(r + 5.0), -0.5 * r, 0.5 * r, r + 5.0].iter().all(|&xi| {
        let start =
            Pose { x: base[0] + xi * xhat[0], y: base[1] + xi * xhat[1], theta: u.to_radians() };
        let end = crate::motion::integrate::run(body, &field, p, start).pose.theta.to_degrees();
        images.iter().any(|&v| cdist(end, v, period) < 1.0)
    })
}
