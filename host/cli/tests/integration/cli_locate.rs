//! `chladni locate` end to end: a synthetic photo of parts at known poses (perspective, blur,
//! noise, uneven light, a touching pair) gives every pose back through the CLI's JSON, the
//! plot is written, and each kind of bad input is refused with its name (exit 2).

use std::path::PathBuf;

use chladni_core::model::part::Part;
use chladni_media::vision::synth::{Photo, random_poses, render, sample_parts};

use crate::support;
use support::cli::{chladni, json, tmp};

/// Writes a part as the JSON part file format.
fn part_file(p: &Part) -> PathBuf {
    let path = tmp("locate", &format!("{}.json", p.name));
    let v = serde_json::json!({"name": p.name, "outline": p.outline, "holes": p.holes});
    std::fs::write(&path, v.to_string()).unwrap();
    path
}

fn args_with_parts<'a>(photo: &'a str, parts: &'a [String]) -> Vec<&'a str> {
    let mut a = vec!["locate", photo, "--size-mm", "300", "200", "--json"];
    for p in parts {
        a.extend_from_slice(&["--part", p.as_str()]);
    }
    a
}

#[test]
fn every_pose_comes_back_through_the_json_and_the_plot_is_written() {
    let parts = sample_parts();
    let files: Vec<String> =
        parts.iter().map(|p| part_file(p).to_string_lossy().into_owned()).collect();
    let placed = random_poses(&parts, [300.0, 200.0], 5, 1, 6.0, 21);
    let photo = Photo::standard(parts.clone(), placed.clone(), 21);
    let path = tmp("locate", "parts.png");
    render(&photo).save(&path).unwrap();
    let plot = tmp("locate", "plot.png");
    let p = path.to_string_lossy().into_owned();
    let mut a = args_with_parts(&p, &files);
    let plot_s = plot.to_string_lossy().into_owned();
    a.extend_from_slice(&["--plot", plot_s.as_str()]);
    let out = chladni(&a);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v = json(&out);
    let found = v["parts"].as_array().unwrap();
    assert_eq!(found.len(), placed.len(), "{v}");
    assert_eq!(v["unknown"].as_array().unwrap().len(), 0, "{v}");
    for pl in &placed {
        let name = &parts[pl.part].name;
        let l = found
            .iter()
            .filter(|l| l["part"] == name.as_str())
            .min_by(|a, b| {
                let d = |l: &&serde_json::Value| {
                    (l["x_mm"].as_f64().unwrap() - pl.c[0])
                        .hypot(l["y_mm"].as_f64().unwrap() - pl.c[1])
                };
                d(a).total_cmp(&d(b))
            })
            .unwrap();
        let d =
            (l["x_mm"].as_f64().unwrap() - pl.c[0]).hypot(l["y_mm"].as_f64().unwrap() - pl.c[1]);
        assert!(d < 1.0, "{pl:?} {l}");
        assert!(l["score"].as_f64().unwrap() > 0.5, "{l}");
        // The tab is its own mirror image: always reported face up.
        if name != "tab" {
            assert_eq!(l["flipped"].as_bool().unwrap(), pl.flipped, "{pl:?} {l}");
            let e = (l["theta_deg"].as_f64().unwrap() - pl.theta_deg).rem_euclid(360.0);
            assert!(e.min(360.0 - e) < 1.0, "{pl:?} {l}");
        }
    }
    let fig = image::open(&plot).unwrap();
    assert!(fig.width() > 1000 && fig.height() > 600, "{}x{}", fig.width(), fig.height());
    for f in [path, plot] {
        let _ = std::fs::remove_file(f);
    }
}

fn refused(args: &[&str], name: &str, text: &str) {
    let out = chladni(args);
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    let v = json(&out);
    assert_eq!(v["error"], name, "{v}");
    assert!(v["message"].as_str().unwrap().contains(text), "{v}");
}

#[test]
fn bad_input_is_refused_by_name() {
    let parts = sample_parts();
    let files: Vec<String> =
        parts.iter().map(|p| part_file(p).to_string_lossy().into_owned()).collect();
    // Not a photo.
    let text = tmp("locate", "not-a-photo.png");
    std::fs::write(&text, "hello").unwrap();
    let t = text.to_string_lossy().into_owned();
    refused(&args_with_parts(&t, &files), "not_a_photo", "cannot read image");
    // No plate: even noise, nothing to tell the plate from its surroundings.
    let noise = tmp("locate", "noise.png");
    let mut rng = chladni_core::plate::photo::synth::Rng(5);
    image::GrayImage::from_fn(640, 450, |_, _| image::Luma([(rng.uniform() * 255.0) as u8]))
        .save(&noise)
        .unwrap();
    let n = noise.to_string_lossy().into_owned();
    refused(&args_with_parts(&n, &files), "no_plate", "no plate found");
    // Corners outside the image.
    let placed = random_poses(&parts, [300.0, 200.0], 3, 0, 6.0, 4);
    let photo = tmp("locate", "three.png");
    render(&Photo::standard(parts.clone(), placed, 4)).save(&photo).unwrap();
    let ph = photo.to_string_lossy().into_owned();
    let mut a = args_with_parts(&ph, &files);
    a.extend_from_slice(&["--corners", "70", "840", "1215", "860", "1170", "95", "110", "-70"]);
    refused(&a, "corners_outside_image", "corner 3");
    // A part that matches nothing on the plate: a 60 mm square.
    let square = Part::new(
        "square".into(),
        vec![[0.0, 0.0], [60.0, 0.0], [60.0, 60.0], [0.0, 60.0]],
        vec![],
    )
    .unwrap();
    let sq = vec![part_file(&square).to_string_lossy().into_owned()];
    refused(&args_with_parts(&ph, &sq), "nothing_matches", "matches a given part");
    // A part larger than the plate.
    let huge = Part::new(
        "huge".into(),
        vec![[0.0, 0.0], [900.0, 0.0], [900.0, 10.0], [0.0, 10.0]],
        vec![],
    )
    .unwrap();
    let hg = vec![part_file(&huge).to_string_lossy().into_owned()];
    refused(&args_with_parts(&ph, &hg), "part_too_large", "does not fit");
    // A huge image, refused from its header.
    let big = tmp("locate", "huge.png");
    let file = std::io::BufWriter::new(std::fs::File::create(&big).unwrap());
    let mut enc = png::Encoder::new(file, 20_000, 20_000);
    enc.set_color(png::ColorType::Grayscale);
    let mut w = enc.write_header().unwrap().into_stream_writer().unwrap();
    std::io::Write::write_all(&mut w, &[0u8; 20_000]).unwrap();
    drop(w);
    let b = big.to_string_lossy().into_owned();
    refused(&args_with_parts(&b, &files), "too_large", "over the limit of 50 MP");
    for f in [text, noise, photo, big] {
        let _ = std::fs::remove_file(f);
    }
}
