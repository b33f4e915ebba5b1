//! `capture_zone` of `plan --json` and of the `not_whole_plate` failure: the clamp's capture
//! zone ([`chladni_core::planner::capture`]) as researchers and scripts read it.

use serde_json::{Value, json};

use chladni_core::model::plan_file::r4;
use chladni_core::model::plate::PlateModel;
use chladni_core::planner::capture::{Band, CaptureZone, InZone, edge_name};

/// `{"bands": [{"edge": "x = 0", "width_mm", "clear_mm"}], "radius_mm", "floor_mm_s",
/// "outside_mm", "clear_box_mm", "message"}`: `outside_mm` is the plate minus the zone (a
/// `--feed` box, or null), `clear_box_mm` the plate past each band's `clear_mm`, where one
/// mode takes no sampled drop to the clamp (a `--feed` box, or null).
pub(crate) fn zone_json(zone: &CaptureZone, plate: &PlateModel) -> Value {
    json!({"bands": bands_json(&zone.bands), "radius_mm": r4(zone.radius_mm),
        "floor_mm_s": zone.floor_mm_s, "outside_mm": zone.outside_mm(plate),
        "clear_box_mm": zone.clear_box_mm(plate),
        "message": zone.describe(plate)})
}

/// `[{"edge": "x = 0", "width_mm", "clear_mm"}]`: one object per band.
fn bands_json(bands: &[Band]) -> Vec<Value> {
    (bands.iter())
        .map(|b| {
            let (width, clear) = (r4(b.width_mm), r4(b.clear_mm));
            json!({"edge": edge_name(b.edge), "width_mm": width, "clear_mm": clear})
        })
        .collect()
}

/// The failure's zone: [`zone_json`]'s keys with `failed_in` and `failed` (its failed drops
/// that start in the zone, of all).
pub(crate) fn in_zone_json(z: &InZone) -> Value {
    json!({"bands": bands_json(&z.zone.bands), "radius_mm": r4(z.zone.radius_mm),
        "floor_mm_s": z.zone.floor_mm_s, "outside_mm": z.outside_mm,
        "clear_box_mm": z.clear_box_mm,
        "message": z.describe(), "failed_in": z.failed_in, "failed": z.failed})
}

/// `json` with `capture_zone` (the zone, and `drops_in` of `drops` of the whole-plate
/// check's drop points that lie in it) when there is one.
pub fn with_zone(
    mut json: Value,
    zone: Option<&CaptureZone>,
    plate: &PlateModel,
    drops: (usize, usize),
) -> Value {
    let Some(z) = zone else { return json };
    // A `not_whole_plate` failure has its own (with its failed drops): keep it, add the counts.
    if json.get("capture_zone").is_none_or(Value::is_null) {
        json["capture_zone"] = zone_json(z, plate);
    }
    json["capture_zone"]["drops_in"] = json!(drops.0);
    json["capture_zone"]["drops"] = json!(drops.1);
    json
}

#[cfg(test)]
mod tests {
    use super::*;
    use chladni_core::planner::edges::PlateEdge;

    #[test]
    fn the_zone_json_names_its_bands_the_plate_outside_and_the_counts() {
        let text = "[plate]\nname = \"t\"\nsize_mm = [300.0, 200.0]\n[[mode]]\nfreq_hz = 50.0\n\
                    node = { kind = \"line\", angle_deg = 0.0 }\n";
        let plate = PlateModel::parse(text, "t").unwrap();
        let band = Band { edge: PlateEdge::Left, width_mm: 85.0, clear_mm: 160.0 };
        let z = CaptureZone {
            bands: vec![band],
            radius_mm: 20.0,
            floor_mm_s: 20.0 / 3600.0,
            runs: 1,
            compute_s: 0.0,
        };
        let inz = InZone::new(z.clone(), &plate, 3, 4);
        let json = in_zone_json(&inz);
        assert_eq!(json["failed_in"], 3);
        assert_eq!(json["bands"][0]["edge"], "x = 0");
        assert_eq!(json["outside_mm"], json!([85.0, 0.0, 300.0, 200.0]));
        assert_eq!(json["clear_box_mm"], json!([160.0, 0.0, 300.0, 200.0]));
        assert_eq!(json["bands"][0]["clear_mm"], 160.0);
        assert!(json["message"].as_str().unwrap().starts_with("x < 85 mm (clamped edge x = 0)"));
        let json = with_zone(json!({}), Some(&z), &plate, (5, 48));
        assert_eq!(json["capture_zone"]["drops_in"], 5);
        assert_eq!(json["capture_zone"]["outside_mm"][0], 85.0);
        assert_eq!(json["capture_zone"]["clear_box_mm"][0], 160.0);
        // A failure's own zone (with its failed drops) is kept; the counts are added.
        let kept =
            with_zone(json!({"capture_zone": in_zone_json(&inz)}), Some(&z), &plate, (5, 48));
        assert_eq!(
            (kept["capture_zone"]["failed_in"].clone(), kept["capture_zone"]["drops"].clone()),
            (json!(3), json!(48))
        );
        assert_eq!(with_zone(json!({}), None, &plate, (0, 0)), json!({}));
    }
}
