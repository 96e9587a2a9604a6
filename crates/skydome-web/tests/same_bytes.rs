//! The web surface adds nothing: the same frames and options give the same bytes through it as
//! through `skydome::pipeline` directly, on the bundled fish-eye bracket with several option
//! sets; and the page's JSON reaches the pipeline unchanged.

#[path = "../../skydome/tests/common/required.rs"]
mod required;

use skydome::formats::{encode_radiance, PixelPoint, RadianceFormat};
use skydome::pipeline::{self, EncodedFrame, Frames, Input, Options, SunMode};
use skydome_web::{
    decode_split, join_decoded, parse_options, run_frames, run_mixed, times_from_list, Outcome,
    Photo,
};

fn demo() -> (Vec<EncodedFrame>, Vec<f64>) {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../demo");
    let names: Vec<String> = (0..3).map(|i| format!("frame_{i}.jpg")).collect();
    let frames = names
        .iter()
        .map(|n| EncodedFrame {
            name: n.clone(),
            bytes: std::fs::read(format!("{dir}/{n}")).expect("demo frame"),
        })
        .collect();
    let list = std::fs::read_to_string(format!("{dir}/times.txt")).expect("demo times");
    let times = times_from_list("times.txt", &list, &names).expect("times");
    (frames, times)
}

fn direct(frames: Vec<EncodedFrame>, times: Vec<f64>, o: &Options) -> Vec<u8> {
    let input = Input {
        times: Some(times),
        ..Input::new(Frames::Encoded(frames))
    };
    let dome = pipeline::run(input, o, &mut pipeline::no_progress).expect("pipeline");
    encode_radiance(&dome.radiance, &dome.meta, RadianceFormat::Hdr)
        .expect("encode")
        .bytes
}

#[test]
fn web_surface_writes_the_pipelines_bytes() {
    let (frames, times) = demo();
    assert_eq!(times, vec![0.001, 0.004, 0.016]);
    let cases = [
        r#"{}"#,
        r#"{"lens": {"detect": {"model": "stereographic", "fov_deg": 235, "circle": null}},
            "sky": {"crop": true, "north_deg": 37, "sun": "auto"}, "products": {"preview": true}}"#,
        r#"{"lens": {"detect": {"model": "equidistant", "fov_deg": 200, "circle": null}},
            "sky": {"crop": false, "north_deg": 301.5, "sun": {"tap": {"x": 150.5, "y": 120.25}}},
            "weighting": "none"}"#,
    ];
    for json in cases {
        let o = parse_options(json).expect("options");
        let mut events = Vec::new();
        let dome = run_frames(frames.clone(), Some(times.clone()), &o, &mut |s, f| {
            events.push((s.to_string(), f));
            false
        })
        .expect("web run");
        let web = Outcome::from_dome(dome);
        let ours = web.hdr_bytes().expect("hdr");
        assert_eq!(
            ours,
            direct(frames.clone(), times.clone(), &o),
            "options {json}"
        );
        // Progress reached the page: every stage started and ended, in order.
        assert_eq!(events.first().map(|e| e.0.as_str()), Some("decoding"));
        assert_eq!(events.last(), Some(&("pictures".to_string(), 1.0)));
    }
}

#[test]
fn tap_in_the_preview_maps_to_the_input_photo() {
    let (frames, times) = demo();
    let o = parse_options(
        r#"{"lens": {"detect": {"model": "stereographic", "fov_deg": 235, "circle": null}},
            "sky": {"crop": true, "north_deg": 0, "sun": "auto"}}"#,
    )
    .expect("options");
    let web = Outcome::from_dome(
        run_frames(frames.clone(), Some(times.clone()), &o, &mut |_, _| false).expect("run"),
    );
    let g = web.dome().report.geometry.clone().expect("geometry");
    // The horizon's centre in the output is the lens circle's centre in the input.
    let c = web.input_pixel(g.horizon.cx, g.horizon.cy);
    assert!((c.x - g.lens.circle.cx).abs() < 1e-9 && (c.y - g.lens.circle.cy).abs() < 1e-9);
    // A tap given in output pixels, mapped back, lands on the same output pixel as the sun.
    let sun = g.sun.expect("sun detected").pixel;
    let tap = web.input_pixel(sun.x, sun.y);
    let mut o2 = o.clone();
    o2.sky.sun = SunMode::Tap(PixelPoint { x: tap.x, y: tap.y });
    let again = run_frames(frames, Some(times), &o2, &mut |_, _| false).expect("run");
    let s2 = again
        .report
        .geometry
        .expect("geometry")
        .sun
        .expect("tapped sun");
    assert!((s2.pixel.x - sun.x).abs() < 1e-9 && (s2.pixel.y - sun.y).abs() < 1e-9);
}

#[test]
fn cancelling_from_the_page_stops_the_run() {
    let (frames, times) = demo();
    let mut calls = 0;
    let e = run_frames(frames, Some(times), &Options::default(), &mut |s, _| {
        calls += 1;
        s == "calibrating"
    })
    .expect_err("cancelled");
    assert_eq!(skydome_web::sentence(&e.to_string()), "Cancelled.");
    assert!(calls >= 2);
}

#[test]
fn times_list_names_the_missing_file() {
    let e = times_from_list(
        "times.txt",
        "a.jpg 1/100\n",
        &["a.jpg".into(), "b.jpg".into()],
    )
    .expect_err("b has no time");
    assert_eq!(
        skydome_web::sentence(&e.to_string()),
        "b.jpg: not listed in times.txt; add a line 'b.jpg TIME'."
    );
}

/// The page names photos by file name, the command line by the paths it was given: one list
/// gives both the same times (the command line calls `skydome::bracket::times_from_list` with
/// the paths), whether it names files by path or by name, in two or three columns.
#[test]
fn times_list_gives_the_page_and_the_command_line_the_same_times() {
    let list = "# Filename exposure 1/shutter_speed\n\
                shots/a.jpg 1/400 400\n\
                /elsewhere/b.jpg 0.01\n\
                c.jpg 0.04 25\n";
    let names: Vec<String> = ["a.jpg", "b.jpg", "c.jpg"].map(String::from).to_vec();
    let paths: Vec<String> = names.iter().map(|n| format!("shots/{n}")).collect();
    let page = times_from_list("times.txt", list, &names).expect("page");
    let cli = skydome::bracket::times_from_list("times.txt", list, &paths).expect("cli");
    assert_eq!(page, [1.0 / 400.0, 0.01, 0.04]);
    assert_eq!(page, cli);

    let dir = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/ssarcandy_street"
    );
    match std::fs::read_to_string(format!("{dir}/image_list.txt")) {
        Ok(list) => {
            let names: Vec<String> = (92..=102).map(|i| format!("DSC_{i:04}.png")).collect();
            let paths: Vec<String> = names.iter().map(|n| format!("{dir}/{n}")).collect();
            let page = times_from_list("image_list.txt", &list, &names).expect("page");
            let cli =
                skydome::bracket::times_from_list("image_list.txt", &list, &paths).expect("cli");
            assert_eq!(page, cli);
            assert_eq!(page[0], 1.0 / 1024.0);
            assert_eq!(page[10], 1.0);
        }
        Err(_) if std::env::var_os("SKYDOME_REQUIRE_SHARED_DATA").is_some() => {
            panic!("{dir}/image_list.txt is missing")
        }
        Err(_) => eprintln!("skipping the ssarcandy list: {dir} is missing"),
    }
}

/// The warm-up the worker runs after loading goes through the whole pipeline without error (a
/// failure here would show as a broken first merge only in the browser).
#[test]
fn warm_up_runs_the_pipeline_on_a_small_synthetic_bracket() {
    skydome_web::warm_up(256).expect("warm-up");
    assert!(skydome_web::warm_up(8).is_err(), "too small for a bracket");
}

/// The decoding warm-up covers both colour layouts a bracket comes in (4:4:4, as `skydome
/// synth` writes; 4:2:0, as phones write: different paths through the JPEG decoder), and its
/// pictures decode through the merge's own decoder to their size.
#[test]
fn decoding_warm_up_covers_444_and_420_jpegs() {
    /// The (horizontal, vertical) sampling factors of each component, from the baseline frame
    /// header (SOF0: FF C0, length, precision, height, width, count, then id, factors, table).
    fn sampling(jpeg: &[u8]) -> Vec<u8> {
        let at = jpeg
            .windows(2)
            .position(|w| w == [0xFF, 0xC0])
            .expect("a baseline frame header");
        let count = usize::from(jpeg[at + 9]);
        (0..count).map(|k| jpeg[at + 11 + 3 * k]).collect()
    }
    let [full, sub] = skydome_web::warm_up_jpegs().expect("the warm-up's pictures");
    assert_eq!(sampling(&full), [0x11, 0x11, 0x11], "4:4:4");
    assert_eq!(sampling(&sub), [0x22, 0x11, 0x11], "4:2:0");
    for bytes in [&full, &sub] {
        let d = skydome::bracket::decode("w.jpg", bytes, &Default::default()).expect("decodes");
        assert_eq!((d.width, d.height), (128, 128));
    }
    skydome_web::warm_up_decoding(2).expect("decoding warm-up");
}

/// The idle reservation returns what it reserved, and 0 (no panic, no abort) for what no
/// memory can hold.
#[test]
fn reserve_heap_reserves_or_declines() {
    assert!(skydome_web::reserve_heap(3 << 20) >= 3 << 20);
    assert_eq!(skydome_web::reserve_heap(usize::MAX), 0);
}

/// The overlay picture made on request after a run that did not make it is the run's own.
#[test]
fn overlay_on_request_is_the_runs_overlay() {
    let (frames, times) = demo();
    let json = |overlay: bool| {
        format!(
            r#"{{"lens": {{"detect": {{"model": "stereographic", "fov_deg": 235, "circle": null}}}},
                "sky": {{"crop": true, "north_deg": 37, "sun": "auto"}},
                "products": {{"preview": true, "overlay": {overlay}}}}}"#
        )
    };
    let run = |overlay: bool| {
        let o = parse_options(&json(overlay)).expect("options");
        Outcome::from_dome(
            run_frames(frames.clone(), Some(times.clone()), &o, &mut |_, _| false).expect("run"),
        )
    };
    let (made, later) = (run(true), run(false));
    assert!(made.dome().overlay.is_some() && later.dome().overlay.is_none());
    let a = made.picture_jpeg(true).expect("overlay");
    assert_eq!(a, later.picture_jpeg(true).expect("overlay on request"));
    assert_ne!(a, later.picture_jpeg(false).expect("preview"));
}

/// Photos decoded in other workers (split into metadata and bytes, put back together), alone or
/// mixed with photos decoded in the run, give the bytes the pipeline writes from the files; EXIF
/// survives the trip (the times come from it in the second set); a broken photo fails with the
/// message the run gives; parts that do not belong together are refused.
#[test]
fn photos_decoded_in_other_workers_give_the_same_bytes() {
    let (demo_frames, demo_times) = demo();
    let fisheye = r#"{"lens": {"detect": {"model": "stereographic", "fov_deg": 235, "circle": null}},
            "sky": {"crop": true, "north_deg": 37, "sun": "auto"}, "products": {"preview": true}}"#;
    let mut sets = vec![(demo_frames, Some(demo_times), fisheye)];
    if let Some(shared) = required::shared_data("frobisher_001") {
        let mut v: Vec<EncodedFrame> = std::fs::read_dir(&shared)
            .expect("frobisher_001")
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|x| x == "jpg"))
            .map(|p| EncodedFrame {
                name: p
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default(),
                bytes: std::fs::read(&p).expect("frobisher frame"),
            })
            .collect();
        v.sort_by(|a, b| a.name.cmp(&b.name));
        assert_eq!(v.len(), 3);
        sets.push((v, None, "{}"));
    }
    for (frames, times, json) in sets {
        let o = parse_options(json).expect("options");
        let want = Outcome::from_dome(
            run_frames(frames.clone(), times.clone(), &o, &mut |_, _| false).expect("files"),
        )
        .hdr_bytes()
        .expect("hdr");
        // Every photo decoded elsewhere, then only the middle one.
        for elsewhere in [vec![true; frames.len()], vec![false, true, false]] {
            let photos = frames
                .iter()
                .zip(&elsewhere)
                .map(|(f, &e)| match e {
                    true => {
                        let (meta, pixels) = decode_split(&f.name, &f.bytes).expect("decode");
                        Photo::Decoded(Box::new(join_decoded(&meta, pixels).expect("join")))
                    }
                    false => Photo::Encoded(f.clone()),
                })
                .collect();
            let got = run_mixed(photos, times.clone(), &o, &mut |_, _| false).expect("mixed run");
            let got = Outcome::from_dome(got).hdr_bytes().expect("hdr");
            assert!(
                got == want,
                "{json}: decoded elsewhere {elsewhere:?} changed the bytes"
            );
        }
    }

    let (frames, _) = demo();
    let mut broken = frames[1].bytes.clone();
    broken.truncate(broken.len() / 3);
    let cut = EncodedFrame {
        name: "cut.jpg".into(),
        bytes: broken.clone(),
    };
    let in_run = run_frames(
        vec![frames[0].clone(), cut],
        None,
        &Options::default(),
        &mut |_, _| false,
    )
    .expect_err("cut photo");
    let elsewhere = decode_split("cut.jpg", &broken).expect_err("cut photo");
    assert_eq!(elsewhere.to_string(), in_run.to_string());
    assert!(
        elsewhere.to_string().starts_with("cut.jpg: "),
        "{elsewhere}"
    );

    let (meta, mut pixels) = decode_split(&frames[0].name, &frames[0].bytes).expect("decode");
    pixels.pop();
    let e = join_decoded(&meta, pixels).expect_err("short pixels");
    assert!(e.to_string().contains("do not make a"), "{e}");
}
