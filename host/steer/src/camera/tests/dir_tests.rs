//! Folder cameras, on real files whose modification times the tests set.

use std::fs::{self, File};
use std::path::{Path, PathBuf};
use std::thread;
use std::time::{Duration, SystemTime};

use image::ImageFormat;

use super::{encoded, failed, photo, quick};
use crate::camera::{Camera, CameraOptions, CameraSource, digest};

/// Writes `bytes` to `dir/name` with modification time `t`.
fn put(dir: &Path, name: &str, bytes: &[u8], t: SystemTime) -> PathBuf {
    let file = dir.join(name);
    fs::write(&file, bytes).expect("a temp folder is writable");
    File::options().write(true).open(&file).and_then(|f| f.set_modified(t)).expect("set mtime");
    file
}

fn open(dir: &Path, options: CameraOptions) -> Camera {
    let source: CameraSource = format!("dir:{}", dir.display()).parse().expect("a dir source");
    Camera::open(source, options).expect("a folder opens")
}

fn ago(s: u64) -> SystemTime {
    SystemTime::now() - Duration::from_secs(s)
}

#[test]
fn the_newest_image_by_modification_time_is_the_frame() {
    let tmp = tempfile::tempdir().expect("a temp folder");
    let png = |seed| encoded(&photo(seed), ImageFormat::Png);
    put(tmp.path(), "a.png", &png(1), ago(3));
    let newest = png(2);
    put(tmp.path(), "b.PNG", &newest, ago(1));
    put(tmp.path(), "c.jpg", &encoded(&photo(3), ImageFormat::Jpeg), ago(2));
    // Not images by name, though newer: ignored.
    put(tmp.path(), "notes.txt", b"hello", SystemTime::now());
    put(tmp.path(), "d.png.part", &png(4), SystemTime::now());
    fs::create_dir(tmp.path().join("sub.png")).expect("a sub-folder");
    let mut cam = open(tmp.path(), CameraOptions::default());
    let f = cam.frame_after(ago(5)).expect("the newest image");
    assert_eq!((f.digest, f.bytes), (digest(&newest), newest.len()));
    assert_eq!(f.image, photo(2));
    let mtime = fs::metadata(tmp.path().join("b.PNG")).and_then(|m| m.modified()).expect("mtime");
    assert_eq!(f.taken, mtime);
}

#[test]
fn a_file_written_later_is_waited_for() {
    let tmp = tempfile::tempdir().expect("a temp folder");
    put(tmp.path(), "old.png", &encoded(&photo(1), ImageFormat::Png), ago(10));
    let fresh = encoded(&photo(2), ImageFormat::Jpeg);
    let not_before = SystemTime::now();
    let (dir, bytes) = (tmp.path().to_path_buf(), fresh.clone());
    let writer = thread::spawn(move || {
        // The delay is the stimulus, not a wait: the camera must find the folder without a
        // new file first and keep polling (the test waits on the frame, not on time).
        thread::sleep(Duration::from_millis(150));
        // Written under another name and renamed, as cameras do, so it is never half-seen.
        fs::write(dir.join("new.tmp"), &bytes).expect("writable");
        fs::rename(dir.join("new.tmp"), dir.join("new.jpg")).expect("renamed");
    });
    let mut cam = open(tmp.path(), CameraOptions::default());
    let f = cam.frame_after(not_before).expect("the file written later");
    writer.join().expect("the writer does not panic");
    assert_eq!(f.digest, digest(&fresh));
    assert!(f.taken >= not_before);
}

#[test]
fn a_broken_newest_file_is_named_after_one_more_read() {
    let tmp = tempfile::tempdir().expect("a temp folder");
    let png = encoded(&photo(1), ImageFormat::Png);
    put(tmp.path(), "good.png", &png, ago(3));
    let broken = put(tmp.path(), "cut.png", &png[..png.len() / 3], ago(1));
    let mut cam = open(tmp.path(), quick(1000));
    failed(cam.frame_after(ago(5)), "broken_image", &broken.display().to_string());
    put(tmp.path(), "text.jpg", b"not a jpeg at all", SystemTime::now());
    failed(cam.frame_after(ago(1)), "not_an_image", "not a jpeg");
}

#[test]
fn an_empty_folder_and_a_stale_one_are_named_after_the_timeout() {
    let tmp = tempfile::tempdir().expect("a temp folder");
    put(tmp.path(), "notes.txt", b"hello", SystemTime::now());
    let mut cam = open(tmp.path(), quick(200));
    let dir = tmp.path().display().to_string();
    failed(cam.frame_after(SystemTime::now()), "empty_folder", &dir);
    put(tmp.path(), "old.png", &encoded(&photo(1), ImageFormat::Png), ago(10));
    failed(cam.frame_after(SystemTime::now()), "stale_frames", &dir);
}

#[test]
fn a_path_that_is_no_folder_is_named_when_opened() {
    let tmp = tempfile::tempdir().expect("a temp folder");
    let file = put(tmp.path(), "a.png", b"x", SystemTime::now());
    for path in [file, tmp.path().join("missing")] {
        let e = Camera::open(CameraSource::Dir(path.clone()), CameraOptions::default())
            .expect_err("not a folder");
        assert_eq!(e.name(), "not_a_folder");
        assert!(e.to_string().contains(&path.display().to_string()), "{e}");
    }
}

#[test]
fn five_identical_files_in_a_row_are_a_frozen_camera() {
    let tmp = tempfile::tempdir().expect("a temp folder");
    let png = encoded(&photo(7), ImageFormat::Png);
    let mut cam = open(tmp.path(), quick(1000));
    for k in 0..5u64 {
        let t = ago(100 - k);
        put(tmp.path(), &format!("f{k}.png"), &png, t);
        let r = cam.frame_after(t);
        if k < 4 {
            let f = r.unwrap_or_else(|e| panic!("file {k}: {e}"));
            // The same file read again is the same frame, not another identical one.
            assert_eq!(cam.frame_after(t).map(|g| g.taken).ok(), Some(f.taken));
        } else {
            failed(r, "frozen", "5 times");
        }
    }
}
