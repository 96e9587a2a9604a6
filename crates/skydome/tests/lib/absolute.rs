//! A camera made absolute once (issue 22, part 3): the physically consistent synthetic camera
//! the tests photograph with, the reflected-light meter equation (`--absolute exif`) against
//! it, and what a profile's constant does on frames without EXIF exposure data. The rendered
//! day (calibrate once, every capture absolute) is `sun_sweep::absolute_day`.
//!
//! The camera: the sensor collects `X = C · L · t · S / N²` of its full well per channel (`L`
//! = 179 × the channel's radiance in Radiance's W·sr⁻¹·m⁻², `t` s, ISO `S`, f-number `N`), `C`
//! chosen so that `L = K·N²/(t·S)`, K = 12.5, renders as mid-grey (code 118) in green, as a
//! camera built to ISO 12232 does; then the project's response, shot and read noise and JPEG
//! ([`synth::photograph`]). Its auto-exposure meters the scene's median luminance to mid-grey
//! at f/1.8 (a phone's fixed aperture): the ISO (25–3200, nominal ⅓ stops) that gives about
//! 1/4000 s, then the time in ⅓ stops; the full well shrinks as the ISO rises.

use skydome::bracket::{DecodedFrame, Frame};
use skydome::camera::{AbsoluteConstant, AbsoluteFrom, CameraProfile};
use skydome::image::{radiance_luminance, HdrImage};
use skydome::photometry::FROM_METER_EQUATION;
use skydome::pipeline::{self, AbsoluteMode, Frames, Input, Options, ResponseSource};
use skydome::synth::{self, SynthOptions};

/// The meter equation's constant (cd·s/m² per ISO).
const K: f64 = 12.5;

/// The phone's fixed aperture.
const F_NUMBER: f64 = 1.8;

/// Full well at the base ISO 25, electrons (the sun sweep's phone-like sensor).
const FULL_WELL_BASE_ISO: f64 = 20_000.0;

/// One capture's exposure: the EV 0 frame's time (s), ISO speed, f-number.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Settings {
    pub time_s: f64,
    pub iso: f64,
    pub f_number: f64,
}

/// The ISO speeds the camera offers, nominal ⅓-stop values (what EXIF records; the sensor's
/// gain follows the nominal value).
const ISO_STEPS: [f64; 22] = [
    25.0, 32.0, 40.0, 50.0, 64.0, 80.0, 100.0, 125.0, 160.0, 200.0, 250.0, 320.0, 400.0, 500.0,
    640.0, 800.0, 1000.0, 1250.0, 1600.0, 2000.0, 2500.0, 3200.0,
];

/// The shutter time the auto-exposure prefers, s (it moves the ISO first).
const PREFERRED_TIME_S: f64 = 1.0 / 4000.0;

/// The auto-exposure for a scene of median luminance `median` (cd/m²): `t·S = K·N²/L`, the ISO
/// nearest to that at 1/4000 s, then the time in ⅓ stops (1/16000 to 1/15 s).
pub(crate) fn auto_exposure(median: f64) -> Settings {
    let h = K / median * F_NUMBER * F_NUMBER; // t·S
    let want = h / PREFERRED_TIME_S;
    let iso = ISO_STEPS
        .iter()
        .copied()
        .min_by(|a, b| (a / want).ln().abs().total_cmp(&(b / want).ln().abs()))
        .unwrap_or(100.0);
    let t = ((3.0 * (h / iso).log2()).round() / 3.0)
        .exp2()
        .clamp(1.0 / 16000.0, 1.0 / 15.0);
    Settings {
        time_s: t,
        iso,
        f_number: F_NUMBER,
    }
}

/// The median Radiance luminance (cd/m²) of the pixels `keep` accepts.
pub(crate) fn median_luminance(img: &HdrImage, keep: impl Fn(usize, usize) -> bool) -> f64 {
    let mut lum: Vec<f64> = (0..img.width * img.height)
        .filter(|i| keep(i % img.width, i / img.width))
        .map(|i| radiance_luminance(img.pixel(i % img.width, i / img.width).map(f64::from)))
        .collect();
    let mid = lum.len() / 2;
    *lum.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Photographs `seen` (Radiance W·sr⁻¹·m⁻² reaching the sensor: the scene after the lens's
/// fall-off) with the camera `opts` (its noise, response, JPEG, EVs) at `s`; the frames carry
/// their time, ISO and f-number as EXIF would.
pub(crate) fn photograph(seen: &HdrImage, opts: &SynthOptions, s: Settings) -> Vec<DecodedFrame> {
    let opts = SynthOptions {
        base_time_s: s.time_s,
        full_well: FULL_WELL_BASE_ISO * 25.0 / s.iso,
        ..opts.clone()
    };
    let c = opts.crf[1].inverse(118.0 / 255.0) / K;
    // synth::photograph collects X = image · 2^EV / 4 of the full well.
    let k = (4.0 * c * 179.0 * s.time_s * s.iso / (s.f_number * s.f_number)) as f32;
    let mut img = seen.clone();
    img.data.iter_mut().for_each(|v| *v *= k);
    synth::photograph(&img, &opts)
        .expect("photograph")
        .into_iter()
        .map(|f: Frame| {
            let mut f = f;
            f.exposure.iso = Some(s.iso);
            f.exposure.f_number = Some(s.f_number);
            DecodedFrame::from(f)
        })
        .collect()
}

/// A sky-like scene, no lens: luminance from about 300 to 30,000 cd/m² across the frame,
/// bluish at the top, whiter low down, with a bright cloud.
fn scene(n: usize) -> HdrImage {
    let mut img = HdrImage::new(n, n);
    for y in 0..n {
        for x in 0..n {
            let (u, v) = (x as f64 / n as f64, y as f64 / n as f64);
            let l = 300.0 * 100f64.powf(0.6 * v + 0.4 * u);
            let cloud = ((u - 0.3).powi(2) + (v - 0.4).powi(2) < 0.01) as u8 as f64;
            let l = l * (1.0 + 3.0 * cloud) / 179.0;
            let tint = 0.25 * (1.0 - v);
            img.set_pixel(
                x,
                y,
                [l * (1.0 - tint), l, l * (1.0 + 2.0 * tint)].map(|c| c as f32),
            );
        }
    }
    img
}

fn camera() -> SynthOptions {
    SynthOptions {
        evs: vec![-2.0, 0.0, 2.0],
        seed: 2222,
        read_noise: 2.0,
        jpeg_quality: Some(95),
        fisheye: false,
        ..SynthOptions::default()
    }
}

fn run(frames: Vec<DecodedFrame>, o: &Options) -> Result<pipeline::Dome, pipeline::PipelineError> {
    pipeline::run(
        Input::new(Frames::Decoded(frames)),
        o,
        &mut pipeline::no_progress,
    )
}

/// `--absolute exif` on the K-consistent camera: the dome's median luminance within the stated
/// ±30 % of the scene's, at three auto-exposures (bright, dim, dim enough for ISO to rise);
/// labelled an estimate in the header and the report.
#[test]
fn the_meter_equation_lands_within_its_stated_uncertainty() {
    let truth = scene(96);
    let o = Options {
        absolute: AbsoluteMode::Exif,
        ..Options::default()
    };
    for dim in [1.0, 1.0 / 16.0, 1.0 / 1024.0] {
        let mut scene = truth.clone();
        scene.data.iter_mut().for_each(|v| *v *= dim as f32);
        let median = median_luminance(&scene, |_, _| true);
        let s = auto_exposure(median);
        let dome = run(photograph(&scene, &camera(), s), &o).expect("merge");
        let p = dome.report.photometry.expect("absolute");
        assert_eq!(p.from, FROM_METER_EQUATION);
        assert_eq!(p.uncertainty_percent, Some(30.0));
        let units = dome
            .meta
            .other
            .iter()
            .find(|l| l.starts_with("#UNITS= absolute"))
            .expect("units line");
        assert!(
            units.contains("meter equation (K = 12.5), an estimate") && units.contains("+/-30 %"),
            "{units}"
        );
        let got = median_luminance(&dome.radiance, |_, _| true);
        let err = got / median - 1.0;
        eprintln!(
            "scene median {median:.1} cd/m2 at 1/{:.0} s ISO {} f/{}: dome median {got:.1} cd/m2 ({:+.1} %)",
            1.0 / s.time_s,
            s.iso,
            s.f_number,
            100.0 * err
        );
        assert!(err.abs() < 0.30, "{:+.1} % is outside ±30 %", 100.0 * err);
    }
}

/// A profile's constant makes a capture at other settings absolute; the same profile on frames
/// without ISO gives a warning naming them and a relative dome; `--absolute exif` on such
/// frames is refused; a profile without the constant (every profile written before it) loads
/// and merges relative, its JSON without the field.
#[test]
fn a_profiles_constant_needs_exif_exposure_data() {
    let truth = scene(64);
    let median = median_luminance(&truth, |_, _| true);
    let s = auto_exposure(median);
    let frames = photograph(&truth, &camera(), s);
    let dome = run(frames.clone(), &Options::default()).expect("calibrate");
    let mut profile = dome.camera_profile.expect("profile");
    assert!(profile.absolute.is_none());
    let old_json = profile.to_json();
    assert!(!old_json.contains("absolute"), "{old_json}");
    assert!(CameraProfile::from_json(&old_json)
        .unwrap()
        .absolute
        .is_none());
    // The constant the meter equation gives this response, stored as a meter reading would.
    let c = AbsoluteConstant::from_meter_equation(&profile.response().unwrap()).unwrap();
    profile.absolute = Some(AbsoluteConstant {
        from: AbsoluteFrom::Illuminance,
        uncertainty_percent: None,
        ..c
    });
    let with = Options {
        response: ResponseSource::Profile(CameraProfile::from_json(&profile.to_json()).unwrap()),
        ..Options::default()
    };
    // Another capture, 3 stops dimmer: its own time and ISO.
    let mut dim = truth.clone();
    dim.data.iter_mut().for_each(|v| *v /= 8.0);
    let s2 = auto_exposure(median / 8.0);
    let frames2 = photograph(&dim, &camera(), s2);
    let dome = run(frames2.clone(), &with).expect("merge");
    let got = median_luminance(&dome.radiance, |_, _| true);
    assert!(dome.report.photometry.is_some());
    assert!(
        (got / (median / 8.0) - 1.0).abs() < 0.3,
        "{got} vs {}",
        median / 8.0
    );
    // Without ISO: a warning and a relative dome.
    let mut no_iso = frames2.clone();
    for f in &mut no_iso {
        f.iso = None;
    }
    let dome = run(no_iso.clone(), &with).expect("merge");
    assert!(dome.report.photometry.is_none());
    assert!(!dome.meta.other.iter().any(|l| l.contains("#UNITS")));
    let w = dome
        .report
        .warnings
        .iter()
        .find(|w| w.contains("absolute constant"))
        .expect("a warning");
    assert!(
        w.contains("have no ISO speed in EXIF") && w.contains("the dome is relative"),
        "{w}"
    );
    // Asked outright, the meter equation refuses them.
    let exif = Options {
        absolute: AbsoluteMode::Exif,
        ..Options::default()
    };
    let e = run(no_iso, &exif).expect_err("refused");
    assert!(e.to_string().contains("have no ISO speed"), "{e}");
    // A reading on such frames makes the dome absolute but gives no constant, and says why.
    let mut no_n = frames.clone();
    for f in &mut no_n {
        f.f_number = None;
    }
    let spot = Options {
        reference: skydome::photometry::Reference {
            luminance: Some(skydome::photometry::SpotLuminance {
                pixel: skydome::image::PixelPoint { x: 32.0, y: 32.0 },
                radius_px: 4.0,
                cd_per_m2: 1000.0,
            }),
            illuminance_lux: None,
        },
        ..Options::default()
    };
    let dome = run(no_n, &spot).expect("merge");
    assert!(dome.report.photometry.is_some());
    assert!(dome.camera_profile.expect("profile").absolute.is_none());
    assert!(dome
        .absolute_constant_refused
        .expect("a reason")
        .contains("have no f-number"));
}
