//! Decoding and validating the real photo sets in `../shared/data`.

use std::path::Path;

use crate::common::data_dir as shared;

use skydome::bracket::{assemble, decode, DecodeOptions, OrientationPolicy};

fn load(dir: &Path, names: &[&str]) -> Vec<skydome::bracket::DecodedFrame> {
    names
        .iter()
        .map(|n| {
            let bytes = std::fs::read(dir.join(n)).unwrap();
            decode(n, &bytes, &DecodeOptions::default()).unwrap()
        })
        .collect()
}

#[test]
fn frobisher_exposure_times_come_from_exif_alone() {
    let Some(d) = shared() else { return };
    let dec = load(
        &d.join("frobisher_001"),
        &["IMG_2601.jpg", "IMG_2602.jpg", "IMG_2600.jpg"],
    );
    let br = assemble(dec, None, OrientationPolicy::Apply).unwrap();
    let times: Vec<f64> = br.frames.iter().map(|f| f.exposure.time_s).collect();
    assert_eq!(times, vec![0.125, 1.0, 8.0]);
    assert_eq!(br.info.make.as_deref(), Some("Canon"));
    assert!(br.info.model.as_deref().unwrap().contains("5D Mark II"));
    assert_eq!(br.frames[0].exposure.f_number, Some(8.0));
    assert_eq!(br.frames[0].exposure.iso, Some(100.0));
    assert!(br.info.datetime_original.is_some());
    assert_eq!((br.width(), br.height()), (640, 426));
    assert!(br.warnings.is_empty(), "{:?}", br.warnings);
}

#[test]
fn banterle_alignment_out_of_order_files_are_sorted_by_exif_time() {
    let Some(d) = shared() else { return };
    let dec = load(
        &d.join("banterle_alignment"),
        &["IMG_4209.jpg", "IMG_4210.jpg", "IMG_4211.jpg"],
    );
    let br = assemble(dec, None, OrientationPolicy::Apply).unwrap();
    let names: Vec<&str> = br.frames.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["IMG_4210.jpg", "IMG_4209.jpg", "IMG_4211.jpg"]);
}

#[test]
fn ssarcandy_adobe_rgb_profile_gives_a_warning() {
    let Some(d) = shared() else { return };
    let dec = load(
        &d.join("ssarcandy_street"),
        &["DSC_0092.png", "DSC_0096.png"],
    );
    assert!(dec[0].non_srgb_icc.as_deref().unwrap().contains("Adobe"));
    let br = assemble(
        dec,
        Some(&[1.0 / 1024.0, 1.0 / 64.0]),
        OrientationPolicy::Apply,
    )
    .unwrap();
    assert!(br.warnings.iter().any(|w| w.contains("not sRGB")));
}

#[test]
fn no_real_set_is_mistaken_for_identical_frames() {
    let Some(d) = shared() else { return };
    let room: Vec<String> = (0..7).map(|i| format!("stack_room_exp_{i}.jpg")).collect();
    let names: Vec<&str> = room.iter().map(String::as_str).collect();
    let dec = load(&d.join("banterle_room"), &names);
    assemble(dec, None, OrientationPolicy::Apply).unwrap();
    let sky: Vec<String> = (0..13)
        .map(|i| format!("Alpnach_20180129_11-09-20_ExposureStack_Image_{i:02}_image.png"))
        .collect();
    let names: Vec<&str> = sky.iter().map(String::as_str).collect();
    let dec = load(&d.join("skycam_alpnach_fisheye"), &names);
    let times: Vec<f64> = (0..13).map(|i| 2f64.powi(i)).collect();
    assemble(dec, Some(&times), OrientationPolicy::Apply).unwrap();
}

#[test]
fn ssarcandy_three_column_list_matches_its_11_files_by_base_name() {
    let Some(d) = shared() else { return };
    let dir = d.join("ssarcandy_street");
    let list = std::fs::read_to_string(dir.join("image_list.txt")).unwrap();
    let paths: Vec<String> = (92..=102)
        .map(|i| dir.join(format!("DSC_{i:04}.png")).display().to_string())
        .collect();
    let times = skydome::bracket::times_from_list("image_list.txt", &list, &paths).unwrap();
    let want: Vec<f64> = (0..11).map(|k| 2f64.powi(k - 10)).collect();
    assert_eq!(times, want);
    // The list names 11 files; a frame it does not name is refused by name.
    let e =
        skydome::bracket::times_from_list("image_list.txt", &list, &["DSC_0091.png"]).unwrap_err();
    assert_eq!(
        e.to_string(),
        "DSC_0091.png: not listed in image_list.txt; add a line 'DSC_0091.png TIME'"
    );
    // A third column that is not 1/time names its line.
    let bad = list.replace("0.125           8", "0.125          16");
    let e = skydome::bracket::parse_list_file("image_list.txt", &bad).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("image_list.txt line 5: third column 16 is not 1/time"),
        "{e}"
    );
}
