//! The pipeline's own rules: stages and cancellation, options as JSON, which options need a
//! lens, the orientation still in force, the Radiance view table, the equirectangular defaults,
//! the radiance formats' rules, and the frame the circle is detected on.

use std::ops::ControlFlow;

use skydome::bracket::{self, CaptureInfo, DecodedFrame, OrientationPolicy, Pixels};
use skydome::fisheye::{self, LensKind};
use skydome::formats::exr::{ExrOptions, ExrPixelType};
use skydome::formats::{self, HdrMeta, RadianceError, RadianceFormat};
use skydome::image::HdrImage;
use skydome::pipeline::{
    self, EncodedFrame, Frames, Input, LensSource, Options, PipelineError, Progress, SkyOptions,
    Stage,
};

fn demo_input() -> Input {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../demo");
    let frames = (0..3)
        .map(|i| EncodedFrame {
            name: format!("frame_{i}.jpg"),
            bytes: std::fs::read(format!("{dir}/frame_{i}.jpg")).expect("demo frame"),
        })
        .collect();
    Input {
        times: Some(vec![0.001, 0.004, 0.016]),
        ..Input::new(Frames::Encoded(frames))
    }
}

#[test]
fn stages_come_in_order_from_zero_to_one() {
    let mut ev: Vec<Progress> = Vec::new();
    let dome = pipeline::run(demo_input(), &Options::default(), &mut |p| {
        ev.push(*p);
        ControlFlow::Continue(())
    })
    .expect("run");
    let stages: Vec<Stage> = ev.iter().map(|p| p.stage).fold(Vec::new(), |mut v, s| {
        if v.last() != Some(&s) {
            v.push(s);
        }
        v
    });
    use Stage::*;
    assert_eq!(stages, [Decoding, Lens, Calibrating, Merging, Pictures]);
    for s in stages {
        let f: Vec<f64> = ev
            .iter()
            .filter(|p| p.stage == s)
            .map(|p| p.fraction)
            .collect();
        assert_eq!(f.first(), Some(&0.0), "{s:?}");
        assert_eq!(f.last(), Some(&1.0), "{s:?}");
        assert!(f.windows(2).all(|w| w[0] <= w[1]), "{s:?}: {f:?}");
    }
    // Nothing unrequested is made.
    assert!(dome.preview.is_none() && dome.overlay.is_none() && dome.equirect.is_none());
    assert!(dome.confidence.is_none() && dome.lens_profile.is_none());
    assert_eq!(dome.report.response, "calibrated on this bracket");
    assert!(dome.camera_profile.is_some());
}

#[test]
fn cancel_stops_at_the_next_check() {
    for stop in [
        Stage::Decoding,
        Stage::Calibrating,
        Stage::Merging,
        Stage::Pictures,
    ] {
        let mut seen_after = false;
        let r = pipeline::run(demo_input(), &Options::default(), &mut |p| {
            seen_after |= p.stage as u8 > stop as u8;
            match p.stage == stop {
                true => ControlFlow::Break(()),
                false => ControlFlow::Continue(()),
            }
        });
        assert!(matches!(r, Err(PipelineError::Cancelled)), "{stop:?}");
        assert!(!seen_after, "{stop:?}: a later stage ran");
    }
}

#[test]
fn decoded_and_encoded_input_give_the_same_dome() {
    let a = pipeline::run(
        demo_input(),
        &Options::default(),
        &mut pipeline::no_progress,
    )
    .expect("encoded");
    let Frames::Encoded(enc) = demo_input().frames else {
        unreachable!()
    };
    let decoded = enc
        .iter()
        .map(|f| bracket::decode(&f.name, &f.bytes, &Default::default()).expect("decode"))
        .collect();
    let input = Input {
        frames: Frames::Decoded(decoded),
        ..demo_input()
    };
    let b = pipeline::run(input, &Options::default(), &mut pipeline::no_progress).expect("decoded");
    assert_eq!(a.radiance, b.radiance);
    assert_eq!(a.report, b.report);
}

#[test]
fn options_read_from_json_with_defaults() {
    let o: Options = serde_json::from_str("{}").expect("empty options");
    assert_eq!(o, Options::default());
    let text = r#"{"lens":{"detect":{"model":"equisolid","fov_deg":185,"circle":null}},
        "sky":{"crop":true,"north_deg":12.5,"sun":{"tap":{"x":10,"y":20}},"pose":"screen_up"},
        "products":{"preview":true,"equirect":{"width":512}}, "weighting":"none"}"#;
    let o: Options = serde_json::from_str(text).expect("options");
    assert_eq!(
        o.lens,
        LensSource::Detect {
            model: LensKind::Equisolid,
            fov_deg: 185.0,
            circle: None
        }
    );
    assert!(o.sky.crop && o.sky.north_deg == Some(12.5) && o.sky.fov_out_deg == 180.0);
    assert_eq!(o.products.equirect.and_then(|e| e.width), Some(512));
    let back: Options = serde_json::from_str(&serde_json::to_string(&o).expect("ser")).expect("de");
    assert_eq!(back, o);
    assert!(serde_json::from_str::<Options>(r#"{"sky":{"sun":"sideways"}}"#).is_err());
}

#[test]
fn sky_options_without_a_lens_are_refused_before_decoding() {
    let crop = Options {
        sky: SkyOptions {
            crop: true,
            ..SkyOptions::default()
        },
        ..Options::default()
    };
    let mut decoded = false;
    let r = pipeline::run(demo_input(), &crop, &mut |p| {
        decoded |= p.stage == Stage::Decoding;
        ControlFlow::Continue(())
    });
    assert!(matches!(r, Err(PipelineError::NeedsLens(_))), "{r:?}");
    assert!(!decoded);
}

fn frame(name: &str, orientation: u16, pixels: Pixels, t: f64) -> DecodedFrame {
    DecodedFrame {
        name: name.into(),
        width: 4,
        height: 2,
        pixels,
        exif_time_s: Some(t),
        iso: None,
        f_number: None,
        info: CaptureInfo {
            orientation,
            ..CaptureInfo::default()
        },
        non_srgb_icc: None,
    }
}

#[test]
fn orientation_in_force_is_one_once_applied_and_the_stored_value_when_ignored() {
    let px = |k: u8| Pixels::U8((0..24).map(|i| (i * 9 + 7) as u8 / k).collect());
    let frames = || vec![frame("a", 6, px(1), 0.01), frame("b", 6, px(3), 0.04)];
    let applied = bracket::assemble(frames(), None, OrientationPolicy::Apply).expect("apply");
    assert_eq!(applied.pixel_orientation, 1);
    assert_eq!((applied.width(), applied.height()), (2, 4), "rotated");
    let kept = bracket::assemble(frames(), None, OrientationPolicy::Ignore).expect("ignore");
    assert_eq!(kept.pixel_orientation, 6);
    assert_eq!((kept.width(), kept.height()), (4, 2));
    assert_eq!(
        "ignore".parse::<OrientationPolicy>(),
        Ok(OrientationPolicy::Ignore)
    );
    assert!("sideways".parse::<OrientationPolicy>().is_err());
}

#[test]
fn circle_is_found_on_the_best_exposed_frame_with_16_bit_codes_rounded() {
    // 2699 / 257 = 10.502: rounds to 11 (a shift by 8 would give 10).
    let v = 257 * 10 + 129;
    let f = |p: Pixels, t| bracket::Frame {
        name: "f".into(),
        width: 4,
        height: 2,
        pixels: p,
        exposure: bracket::Exposure {
            time_s: t,
            iso: None,
            f_number: None,
        },
    };
    let dark = f(Pixels::U16(vec![v; 24]), 0.01);
    let mid = f(Pixels::U16(vec![257 * 100; 24]), 0.04);
    let best = bracket::best_exposed_u8(&[dark.clone(), mid]);
    assert!(best.data.iter().all(|&z| z == 100));
    let only = bracket::best_exposed_u8(&[dark]);
    assert!(only.data.iter().all(|&z| z == 11));
}

#[test]
fn one_photo_needs_no_exposure_time_for_circle_detection() {
    let Frames::Encoded(mut enc) = demo_input().frames else {
        unreachable!()
    };
    let one = Input::new(Frames::Encoded(vec![enc.remove(1)]));
    let (fit, photo) = pipeline::detect_lens_circle(one).expect("circle");
    // demo/circle.txt: 200,200,192
    assert!((fit.circle.cx - 200.0).abs() < 1.5 && (fit.circle.cy - 200.0).abs() < 1.5);
    assert!((fit.circle.r - 192.0).abs() < 1.5, "{:?}", fit.circle);
    assert_eq!((photo.width, photo.height), (400, 400));
    // Two photos are a bracket: they need their times.
    let two = Input::new(Frames::Encoded(enc));
    match pipeline::detect_lens_circle(two) {
        Err(PipelineError::Bracket(bracket::BracketError::MissingExposure { .. })) => {}
        other => panic!("{other:?}"),
    }
}

#[test]
fn radiance_view_has_the_upward_direction_and_the_image_top() {
    use skydome::fisheye::LensProfile;
    use skydome::image::Circle;
    use skydome::sky::{DevicePose, ImageOrientation, SkyGeometry};
    let c = Circle {
        cx: 100.0,
        cy: 100.0,
        r: 100.0,
    };
    let view = |kind, north, o| {
        let lens = LensProfile::from_fov(c, 180.0, kind).expect("lens");
        SkyGeometry::new(&lens, north, DevicePose::ScreenDown, o)
            .expect("geometry")
            .radiance_view(100.0)
    };
    let n = ImageOrientation::Normal;
    assert_eq!(
        view(LensKind::Equidistant, 0.0, n).as_deref(),
        Some("-vta -vp 0 0 0 -vd 0 0 1 -vu 0 1 0 -vh 180 -vv 180")
    );
    assert_eq!(
        view(LensKind::Stereographic, 0.0, n).as_deref(),
        Some("-vts -vp 0 0 0 -vd 0 0 1 -vu 0 1 0 -vh 180 -vv 180")
    );
    // The phone's top edge pointing east puts east at the image top.
    assert_eq!(
        view(LensKind::Equidistant, 90.0, n).as_deref(),
        Some("-vta -vp 0 0 0 -vd 0 0 1 -vu 1 0 0 -vh 180 -vv 180")
    );
    assert!(view(LensKind::Orthographic, 0.0, n).is_some_and(|v| v.starts_with("-vth ")));
    // No Radiance view type for equisolid; a mirrored image is no Radiance view.
    assert_eq!(view(LensKind::Equisolid, 0.0, n), None);
    assert_eq!(
        view(
            LensKind::Equidistant,
            0.0,
            ImageOrientation::MirrorHorizontal
        ),
        None
    );
    // An image wider than the horizon spans more than 180°.
    let lens = LensProfile::from_fov(c, 180.0, LensKind::Equidistant).expect("lens");
    let g = SkyGeometry::new(&lens, 0.0, DevicePose::ScreenDown, n).expect("geometry");
    assert!(g
        .radiance_view(101.0)
        .is_some_and(|v| v.ends_with("-vh 181.8 -vv 181.8")));
}

#[test]
fn equirect_width_is_four_radii_even_and_bounded() {
    assert_eq!(pipeline::default_equirect_width(192.0), 768);
    assert_eq!(pipeline::default_equirect_width(100.3), 400);
    assert_eq!(pipeline::default_equirect_width(100.6), 402);
    assert_eq!(pipeline::default_equirect_width(3.0), 64);
    assert_eq!(pipeline::default_equirect_width(1e6), 8192);
    let m = HdrMeta {
        capdate: Some("2026:06:21 13:30:00".into()),
        view: Some("-vta".into()),
        north: Some(skydome::formats::PixelPoint { x: 1.0, y: 2.0 }),
        ..HdrMeta::default()
    };
    let e = pipeline::equirect_meta(&m);
    assert_eq!(e.capdate, m.capdate);
    assert!(e.view.is_none() && e.north.is_none() && e.sun.is_none());
}

#[test]
fn half_float_overflow_switches_to_float_and_says_so() {
    let img = HdrImage {
        width: 2,
        height: 1,
        data: vec![1.0, 2.0, 3.0, 1.0e5, 0.5, 7e5],
    };
    let half =
        RadianceFormat::from_extension("EXR", ExrOptions::from(ExrPixelType::Half)).expect("exr");
    let e = formats::encode_radiance(&img, &HdrMeta::default(), half).expect("encode");
    assert_eq!(e.warnings.len(), 1, "{:?}", e.warnings);
    assert_eq!(formats::read_radiance(&e.bytes).expect("read").image, img);
    let small = HdrImage {
        data: vec![1.0; 6],
        ..img
    };
    let e = formats::encode_radiance(&small, &HdrMeta::default(), half).expect("encode");
    assert!(e.warnings.is_empty());
    assert_eq!(
        RadianceFormat::from_extension("tif", ExrOptions::default()),
        None
    );
}

#[test]
fn reading_sniffs_the_signature_and_applies_exposure() {
    let img = HdrImage {
        width: 8,
        height: 1,
        data: (0..24).map(|i| 0.5 + i as f32).collect(),
    };
    let meta = HdrMeta {
        exposure: Some(2.0),
        ..HdrMeta::default()
    };
    let bytes = formats::encode_radiance(&img, &meta, RadianceFormat::Hdr)
        .expect("encode")
        .bytes;
    let r = formats::read_radiance(&bytes).expect("read");
    assert_eq!(r.format, "Radiance RGBE");
    for (a, b) in r.image.data.iter().zip(&img.data) {
        assert!((a * 2.0 - b).abs() <= b / 128.0, "{a} vs {b}");
    }
    assert!(matches!(
        formats::read_radiance(b"P6\n1 1\n255\n\0\0\0"),
        Err(RadianceError::Unrecognised)
    ));
}

#[test]
fn pixel_point_has_one_text_form() {
    use skydome::image::PixelPoint;
    let p: PixelPoint = "-Y 20.5 +X 10.25".parse().expect("point");
    assert_eq!(p, PixelPoint { x: 10.25, y: 20.5 });
    assert_eq!(p.to_string(), "-Y 20.5 +X 10.25");
    let tiny = PixelPoint { x: 1e-9, y: 3.0 };
    assert_eq!(tiny.to_string().parse::<PixelPoint>(), Ok(tiny));
    for bad in [
        "",
        "-Y 1",
        "+X 1 -Y 2",
        "-Y a +X 1",
        "-Y NaN +X 1",
        "-Y 1 +X inf",
    ] {
        assert!(bad.parse::<PixelPoint>().is_err(), "{bad}");
    }
}

#[test]
fn images_are_checked_against_their_size() {
    use skydome::image::RgbImage;
    assert!(RgbImage::try_from_vec(2, 2, vec![0u8; 12]).is_ok());
    let e = RgbImage::try_from_vec(2, 2, vec![0u8; 11]).unwrap_err();
    assert_eq!((e.expected, e.got), (12, 11));
    let broken = RgbImage {
        width: 3,
        height: 1,
        data: vec![0u8; 3],
    };
    assert!(broken.validate().is_err());
    assert!(matches!(
        fisheye::detect_circle(&broken),
        Err(fisheye::FisheyeError::BufferSize(_))
    ));
}

#[test]
fn north_from_the_sun_does_not_depend_on_the_compass() {
    use skydome::pipeline::SunMode;
    let run = |compass: Option<f64>| {
        let o = Options {
            lens: LensSource::Detect {
                model: LensKind::Equidistant,
                fov_deg: 235.0,
                circle: None,
            },
            sky: SkyOptions {
                crop: true,
                north_deg: compass,
                north_from_sun: true,
                sun: SunMode::Auto,
                time: Some("2026-06-21T10:00:00+02:00".into()),
                latitude_deg: Some(47.0),
                longitude_deg: Some(8.3),
                ..SkyOptions::default()
            },
            ..Options::default()
        };
        pipeline::run(demo_input(), &o, &mut pipeline::no_progress).expect("run")
    };
    let a = run(Some(0.0));
    let b = run(Some(40.0));
    let c = run(None);
    let na = a.report.geometry.as_ref().unwrap().north_from_sun.unwrap();
    let nb = b.report.geometry.as_ref().unwrap().north_from_sun.unwrap();
    let nc = c.report.geometry.as_ref().unwrap().north_from_sun.unwrap();
    for n in [nb, nc] {
        let d = (n.north_deg - na.north_deg + 540.0).rem_euclid(360.0) - 180.0;
        assert!(d.abs() < 0.01, "{n:?} vs {na:?}");
    }
    assert_eq!(nc.compass_error_deg, None);
    let e = nb.compass_error_deg.unwrap();
    assert!(((40.0 + e).rem_euclid(360.0) - nb.north_deg).abs() < 1e-9);
    // With that north the observed sun sits at the computed azimuth.
    let g = a.report.geometry.as_ref().unwrap();
    let (sun, eph) = (g.sun.unwrap(), g.sun_ephemeris.unwrap());
    let daz = (sun.azimuth_deg.unwrap() - eph.azimuth_deg + 540.0).rem_euclid(360.0) - 180.0;
    assert!(daz.abs() < 0.05, "{daz}");
    assert!(g.north.is_some() && a.meta.north.is_some());
    // Without a place there is no ephemeris to set north from.
    let o = Options {
        lens: LensSource::Detect {
            model: LensKind::Equidistant,
            fov_deg: 235.0,
            circle: None,
        },
        sky: SkyOptions {
            north_from_sun: true,
            ..SkyOptions::default()
        },
        ..Options::default()
    };
    assert!(matches!(
        pipeline::run(demo_input(), &o, &mut pipeline::no_progress),
        Err(PipelineError::NoEphemeris)
    ));
}

/// A cropped dome needs only the photos' square around it, and the pipeline merges only that
/// square when nothing else reads the rest of the photo (on the phone it keeps the merge's
/// radiance to the dome's size). The dome must be the whole merge's crop bit for bit: the same
/// runs with the confidence map asked for — which merges the whole photo — give the same dome,
/// pictures, maps, header and counts. A frame wider than tall puts the square off the corner.
#[test]
fn a_dome_merged_in_its_square_is_the_whole_merge_cropped() {
    let b = skydome::synth::generate(&skydome::synth::SynthOptions {
        width: 420,
        height: 360,
        ..Default::default()
    })
    .expect("synth");
    let circle = b.circle.expect("a fish-eye bracket");
    let frames =
        || -> Vec<DecodedFrame> { b.frames.iter().cloned().map(DecodedFrame::from).collect() };
    for (sun, north) in [
        (pipeline::SunMode::Auto, Some(30.0)),
        (pipeline::SunMode::None, None),
    ] {
        let part = Options {
            lens: LensSource::Detect {
                model: LensKind::Stereographic,
                fov_deg: 235.0,
                circle: Some(circle),
            },
            sky: SkyOptions {
                crop: true,
                sun,
                north_deg: north,
                ..SkyOptions::default()
            },
            products: pipeline::Products {
                preview: true,
                overlay: true,
                angular: true,
                equirect: Some(pipeline::EquirectOptions::default()),
                ..pipeline::Products::default()
            },
            ..Options::default()
        };
        let mut whole = part.clone();
        whole.products.confidence = true;
        let run = |o: &Options| {
            pipeline::run(
                Input::new(Frames::Decoded(frames())),
                o,
                &mut pipeline::no_progress,
            )
            .expect("run")
        };
        let (a, w) = (run(&part), run(&whole));
        assert!(a.radiance.width < 360 && a.radiance.width == a.radiance.height);
        let bits = |d: &pipeline::Dome| {
            d.radiance
                .data
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>()
        };
        assert_eq!(
            (a.radiance.width, a.radiance.height),
            (w.radiance.width, w.radiance.height)
        );
        assert!(bits(&a) == bits(&w), "the dome differs");
        assert_eq!(a.preview, w.preview);
        assert_eq!(a.overlay, w.overlay);
        assert_eq!(a.equirect, w.equirect);
        assert_eq!(a.angular, w.angular);
        assert_eq!(a.meta, w.meta);
        assert_eq!(a.marks, w.marks);
        let (ra, rw) = (&a.report, &w.report);
        assert_eq!(
            (
                ra.clipped_high_pixels,
                ra.clipped_low_pixels,
                ra.black_pixels
            ),
            (
                rw.clipped_high_pixels,
                rw.clipped_low_pixels,
                rw.black_pixels
            )
        );
        assert!(
            ra.clipped_high_pixels + ra.clipped_low_pixels > 0,
            "the housing and the sun count"
        );
        let json = |g| serde_json::to_string(g).expect("json");
        assert_eq!(json(&ra.geometry), json(&rw.geometry));
        assert!(
            ra.warnings.iter().all(|x| rw.warnings.contains(x)),
            "{:?} {:?}",
            ra.warnings,
            rw.warnings
        );
    }
}

/// A synthetic fish-eye bracket (`evs`, `width × height`) as JPEG files (quality 92), with its
/// exposure times.
fn encoded_bracket(evs: &[f64], width: usize, height: usize) -> (Vec<EncodedFrame>, Vec<f64>) {
    use skydome::formats::picture::{encode_rgb8, PictureFormat};
    use skydome::image::RgbImage;
    let b = skydome::synth::generate(&skydome::synth::SynthOptions {
        width,
        height,
        evs: evs.to_vec(),
        ..Default::default()
    })
    .expect("synth");
    let times = b.frames.iter().map(|f| f.exposure.time_s).collect();
    let encoded = b
        .frames
        .iter()
        .map(|f| {
            let Pixels::U8(v) = &f.pixels else {
                panic!("8-bit synth")
            };
            let img = RgbImage {
                width: f.width,
                height: f.height,
                data: v.clone(),
            };
            EncodedFrame {
                name: format!("{}.jpg", f.name),
                bytes: encode_rgb8(&img, PictureFormat::Jpeg { quality: 92 }).expect("jpeg"),
            }
        })
        .collect();
    (encoded, times)
}

/// The options of a plain crop to the dome (the job the streamed intake reads), with a preview.
fn plain_crop_options() -> Options {
    Options {
        lens: LensSource::Detect {
            model: LensKind::Stereographic,
            fov_deg: 235.0,
            circle: None,
        },
        sky: SkyOptions {
            crop: true,
            sun: pipeline::SunMode::Auto,
            north_deg: Some(10.0),
            ..SkyOptions::default()
        },
        products: pipeline::Products {
            preview: true,
            ..pipeline::Products::default()
        },
        ..Options::default()
    }
}

/// Runs `frames` with `times` and `o`: the dome, and whether the run read the frames one at a
/// time (the streamed intake reports the calibrating stage frame by frame).
fn run_watching(frames: Frames, times: &[f64], o: &Options) -> (pipeline::Dome, bool) {
    let mut per_frame = false;
    let dome = pipeline::run(
        Input {
            times: Some(times.to_vec()),
            ..Input::new(frames)
        },
        o,
        &mut |p: &Progress| {
            per_frame |= p.stage == Stage::Calibrating && p.fraction > 0.0 && p.fraction < 1.0;
            ControlFlow::Continue(())
        },
    )
    .expect("run");
    (dome, per_frame)
}

/// A plain crop of encoded photos above the frame memory budget is read one frame at a time
/// (the scan, then the second pass that gathers the window, the flags and the sampler's
/// values): the run must give what the whole decoded frames give, bit for bit — the dome, its
/// header, the pictures, the report and the camera profile — for a 9- and a 3-frame bracket,
/// the circle detected, with the default calibration, the stratified noise-weighted one,
/// colour-hdri's hat margin, the covering draw and a camera profile. Without a budget, or with
/// one the bracket fits in, the same encoded photos are decoded whole (no streaming), with the
/// same bytes.
#[test]
fn a_bracket_read_one_frame_at_a_time_gives_the_whole_frames_bytes() {
    use skydome::response::CalibrateOptions;
    for evs in [
        vec![-4.0, -3.0, -2.0, -1.0, 0.0, 1.0, 2.0, 3.0, 4.0],
        vec![-2.0, 0.0, 2.0],
    ] {
        let (encoded, times) = encoded_bracket(&evs, 400, 340);
        let size = 3 * 400 * 340 * evs.len() as u64;
        let decoded = || -> Vec<DecodedFrame> {
            encoded
                .iter()
                .map(|e| bracket::decode(&e.name, &e.bytes, &Default::default()).expect("decode"))
                .collect()
        };
        let base = plain_crop_options();
        let noise = Options {
            response: pipeline::ResponseSource::Calibrate(CalibrateOptions::noise_fit()),
            ..base.clone()
        };
        let first = run_watching(Frames::Decoded(decoded()), &times, &base).0;
        // The hat with its ends moved in (colour-hdri's) on the default samples, and the
        // covering draw: both must reach the streamed fit too.
        let margin = Options {
            response: pipeline::ResponseSource::Calibrate(CalibrateOptions {
                hat_margin: skydome::response::COLOUR_HDRI_HAT_MARGIN,
                ..CalibrateOptions::robust()
            }),
            ..base.clone()
        };
        let covering = Options {
            response: pipeline::ResponseSource::Calibrate(CalibrateOptions::covering()),
            ..base.clone()
        };
        let profiled = Options {
            response: pipeline::ResponseSource::Profile(
                first.camera_profile.clone().expect("a profile"),
            ),
            ..base.clone()
        };
        // The calibration the report names: the default's resolved for the frame count.
        let default_name = if evs.len() >= 5 { "covering" } else { "joined" };
        for (o, name) in [
            (&base, Some(default_name)),
            (&noise, Some("noise")),
            (&margin, Some("robust (options changed)")),
            (&covering, Some("covering")),
            (&profiled, None),
        ] {
            let budget = |b: Option<u64>| Options {
                frame_memory_budget: b,
                ..o.clone()
            };
            let (whole, streamed_whole) = run_watching(Frames::Decoded(decoded()), &times, o);
            let (streamed, streamed_flag) = run_watching(
                Frames::Encoded(encoded.clone()),
                &times,
                &budget(Some(size - 1)),
            );
            assert!(!streamed_whole && streamed_flag, "{evs:?}: not streamed");
            let hdr = |d: &pipeline::Dome| {
                formats::encode_radiance(&d.radiance, &d.meta, RadianceFormat::Hdr)
                    .expect("hdr")
                    .bytes
            };
            assert!(hdr(&whole) == hdr(&streamed), "{evs:?}: the .hdr differs");
            assert_eq!(whole.preview, streamed.preview);
            assert_eq!(json(&whole.report), json(&streamed.report), "{evs:?}");
            assert_eq!(streamed.report.calibration.as_deref(), name, "{evs:?}");
            assert_eq!(
                json(&whole.camera_profile),
                json(&streamed.camera_profile),
                "{evs:?}"
            );
            assert!(whole.report.clipped_high_pixels + whole.report.clipped_low_pixels > 0);
            // The gate: no budget, or one the bracket fits in, reads the encoded photos whole.
            for b in [None, Some(size)] {
                let (d, per_frame) =
                    run_watching(Frames::Encoded(encoded.clone()), &times, &budget(b));
                assert!(!per_frame, "{evs:?}, budget {b:?}: streamed");
                assert!(
                    hdr(&d) == hdr(&whole),
                    "{evs:?}, budget {b:?}: the .hdr differs"
                );
            }
        }
    }
}

/// The gate of the streamed intake: encoded photos whose decoded size (from their headers:
/// frames × width × height × 3 bytes) exceeds the budget, with a job that allows it; never
/// without a budget, for decoded frames, or for a job that reads the whole photos.
#[test]
fn the_frames_are_streamed_only_above_the_memory_budget() {
    let (encoded, _) = encoded_bracket(&[-2.0, 0.0, 2.0], 300, 200);
    let size = 3 * 3 * 300 * 200;
    assert_eq!(pipeline::decoded_size(&encoded), size);
    let input = Input::new(Frames::Encoded(encoded.clone()));
    let with = |budget: Option<u64>, f: fn(&mut Options)| {
        let mut o = Options {
            frame_memory_budget: budget,
            ..plain_crop_options()
        };
        f(&mut o);
        o
    };
    let keep = |_: &mut Options| {};
    assert!(pipeline::streams_input(&input, &with(Some(size - 1), keep)));
    assert!(pipeline::streams_input(&input, &with(Some(0), keep)));
    assert!(!pipeline::streams_input(&input, &with(Some(size), keep)));
    assert!(!pipeline::streams_input(&input, &with(None, keep)));
    assert!(!pipeline::streams_input(&input, &Options::default()));
    let decoded: Vec<DecodedFrame> = encoded
        .iter()
        .map(|e| bracket::decode(&e.name, &e.bytes, &Default::default()).expect("decode"))
        .collect();
    let decoded = Input::new(Frames::Decoded(decoded));
    assert!(!pipeline::streams_input(&decoded, &with(Some(0), keep)));
    // Jobs that read the whole photos: no crop, alignment, a ghost-aware merge.
    for f in [
        (|o: &mut Options| o.sky.crop = false) as fn(&mut Options),
        |o| o.align = true,
        |o| o.ghosts = true,
        |o| o.lens = LensSource::None,
    ] {
        assert!(!pipeline::streams_input(&input, &with(Some(0), f)));
    }
    // A photo whose header does not read counts for nothing.
    let mut broken = encoded;
    broken[1].bytes.truncate(4);
    assert_eq!(pipeline::decoded_size(&broken), size / 3 * 2);
}

/// A photo that does not decode, read one at a time (the 5th of 9, cut short): the run ends
/// with the error the whole frames give, one line naming the file.
#[test]
fn a_corrupt_photo_read_one_at_a_time_is_named() {
    let evs = [-4.0, -3.0, -2.0, -1.0, 0.0, 1.0, 2.0, 3.0, 4.0];
    let (mut encoded, times) = encoded_bracket(&evs, 400, 340);
    let n = encoded[4].bytes.len();
    encoded[4].bytes.truncate(n / 2);
    let name = encoded[4].name.clone();
    let input = || Input {
        times: Some(times.clone()),
        ..Input::new(Frames::Encoded(encoded.clone()))
    };
    let streamed = Options {
        frame_memory_budget: Some(0),
        ..plain_crop_options()
    };
    assert!(pipeline::streams_input(&input(), &streamed));
    let mut decoded_after = 0usize;
    let err = pipeline::run(input(), &streamed, &mut |p: &Progress| {
        decoded_after += usize::from(p.stage != Stage::Decoding);
        ControlFlow::Continue(())
    })
    .expect_err("a corrupt photo");
    let msg = err.to_string();
    assert!(msg.contains(&name), "{msg}");
    assert!(!msg.contains('\n'), "{msg}");
    assert_eq!(decoded_after, 0, "the run went past decoding");
    let whole = pipeline::run(input(), &plain_crop_options(), &mut pipeline::no_progress)
        .expect_err("a corrupt photo");
    assert_eq!(msg, whole.to_string());
}

fn json<T: serde::Serialize>(v: &T) -> String {
    serde_json::to_string(v).expect("json")
}
