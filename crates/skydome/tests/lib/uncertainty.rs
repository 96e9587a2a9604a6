//! The standard error the merge states ([`merge::standard_error`]) against the error it makes,
//! on synthetic brackets whose response and noise are known.

use skydome::merge::{self, MergeOptions, Weighting};
use skydome::noise::{ChannelNoise, NoiseModel};
use skydome::response::Response;
use skydome::synth::{self, SynthOptions};

/// With the true response and noise model, |log2 error| / σ over the measured pixels has the
/// median of a unit normal's absolute value (0.674) and its 90th percentile (1.645).
#[test]
fn stated_standard_error_matches_the_error_distribution() {
    for (weighting, seed) in [(Weighting::Noise, 31u64), (Weighting::Hat, 32)] {
        let opts = SynthOptions {
            width: 256,
            height: 256,
            seed,
            jpeg_quality: None,
            full_well: 4000.0,
            read_noise: 3.0,
            ..SynthOptions::default()
        };
        let b = synth::generate(&opts).unwrap();
        // The true curves with g(128) = 0, and the noise model they imply.
        let gauge: Vec<f64> = b.true_g.iter().map(|g| g[128]).collect();
        let curves = std::array::from_fn(|c| b.true_g[c].iter().map(|v| v - gauge[c]).collect());
        let response = Response::from_curves(curves).unwrap();
        let noise = NoiseModel {
            channels: std::array::from_fn(|c| ChannelNoise {
                electrons_at_gauge: gauge[c].exp() * opts.full_well,
                read_noise: opts.read_noise,
                code_noise: 0.0,
            }),
        };
        let m = merge::merge(
            &b.frames,
            &response,
            &MergeOptions {
                weighting,
                noise: Some(noise),
                clipped_mask: true,
                ..MergeOptions::default()
            },
        )
        .unwrap();
        let lt: Vec<f64> = b
            .frames
            .iter()
            .map(|f| f.exposure.relative().ln())
            .collect();
        let sigma = merge::standard_error(
            &m.radiance,
            m.clipped.as_deref(),
            &lt,
            &response,
            &noise,
            weighting,
            0,
        );
        let mut z = Vec::new();
        for k in 0..m.radiance.data.len() {
            let (e, t, s) = (m.radiance.data[k], b.truth.data[k], sigma.data[k]);
            if t > 0.0 && e > 0.0 && s.is_finite() {
                let expected = f64::from(t) * b.exposure_scale / gauge[k % 3].exp();
                z.push((f64::from(e) / expected).log2().abs() / f64::from(s));
            }
        }
        z.sort_by(f64::total_cmp);
        let med = z[z.len() / 2];
        let p90 = z[z.len() * 9 / 10];
        let summary = merge::summarise_standard_error(&sigma, None);
        eprintln!(
            "{weighting:?}: |error|/σ over {} samples: median {med:.3} (normal 0.674), p90 {p90:.3} (normal 1.645); median σ {:.4} stops, {:.2} % not measured",
            z.len(),
            summary.0,
            100.0 * summary.2
        );
        assert!(
            (med - 0.674).abs() < 0.1,
            "{weighting:?}: median |error|/σ {med:.3}"
        );
        assert!(
            (p90 - 1.645).abs() < 0.3,
            "{weighting:?}: p90 |error|/σ {p90:.3}"
        );
    }
}
