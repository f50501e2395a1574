//! Error of a lightmap against a reference, over the texels both hold.
//!
//! With estimate `x` and reference `r` per texel and RGB channel, over the `n` values compared:
//! - RMSE `= sqrt(Σ (x − r)² / n)`;
//! - relative MSE `= Σ (x − r)² / (r² + ε) / n`, with `ε = 10⁻² · r̄²` (r̄ the mean reference
//!   value), so texels darker than about a tenth of the mean do not dominate it, and the measure
//!   does not change when the scene's light is scaled;
//! - mean bias `= Σ (x − r) / n`, and relative bias `= mean bias / r̄`.
//!
//! A reference that is itself a Monte Carlo estimate adds its own variance to every MSE: the
//! harness makes the reference with many more samples than any run it measures.

use serde::Serialize;

/// The factor of `ε = EPSILON_FACTOR · r̄²` in the relative MSE.
pub const EPSILON_FACTOR: f64 = 1e-2;

/// Errors of one lightmap against the reference.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ErrorStats {
    /// Root mean squared error (irradiance units).
    pub rmse: f64,
    /// Relative mean squared error (dimensionless).
    pub rel_mse: f64,
    /// Mean signed error (irradiance units).
    pub bias: f64,
    /// Mean signed error over the mean reference value.
    pub rel_bias: f64,
    /// Texels compared.
    pub texels: u64,
}

/// Why two lightmaps could not be compared.
#[derive(Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct CompareError(String);

impl CompareError {
    /// An error saying `what`.
    pub(crate) fn new(what: String) -> Self {
        Self(what)
    }
}

/// Compares `estimate` with `reference`, texel by texel (same indexing, `None` for texels a
/// lightmap does not hold); texels where either is missing or non-finite are left out.
///
/// # Errors
/// [`CompareError`] when the lengths differ or no texel can be compared.
pub fn compare(
    estimate: &[Option<[f32; 3]>],
    reference: &[Option<[f32; 3]>],
) -> Result<ErrorStats, CompareError> {
    if estimate.len() != reference.len() {
        return Err(CompareError(format!(
            "{} texels against a reference of {}",
            estimate.len(),
            reference.len()
        )));
    }
    let finite = |v: &[f32; 3]| v.iter().all(|c| c.is_finite());
    let pairs: Vec<([f32; 3], [f32; 3])> = estimate
        .iter()
        .zip(reference)
        .filter_map(|(x, r)| Some(((*x)?, (*r)?)))
        .filter(|(x, r)| finite(x) && finite(r))
        .collect();
    if pairs.is_empty() {
        return Err(CompareError(
            "no texel holds a finite value in both the lightmap and the reference".into(),
        ));
    }
    let n = (pairs.len() * 3) as f64;
    let values = || {
        pairs
            .iter()
            .flat_map(|(x, r)| (0..3).map(move |c| (f64::from(x[c]), f64::from(r[c]))))
    };
    let mean_ref = values().map(|(_, r)| r).sum::<f64>() / n;
    let epsilon = (EPSILON_FACTOR * mean_ref * mean_ref).max(f64::MIN_POSITIVE);
    let (mut sq, mut rel, mut signed) = (0.0, 0.0, 0.0);
    for (x, r) in values() {
        let d = x - r;
        sq += d * d;
        rel += d * d / (r * r + epsilon);
        signed += d;
    }
    let bias = signed / n;
    Ok(ErrorStats {
        rmse: (sq / n).sqrt(),
        rel_mse: rel / n,
        bias,
        rel_bias: if mean_ref > 0.0 { bias / mean_ref } else { 0.0 },
        texels: pairs.len() as u64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lightmap_has_no_error_against_itself() {
        let a = vec![Some([1.0, 2.0, 3.0]), None, Some([0.5, 0.0, 4.0])];
        let e = compare(&a, &a).unwrap();
        assert_eq!((e.rmse, e.rel_mse, e.bias, e.texels), (0.0, 0.0, 0.0, 2));
    }

    #[test]
    fn an_offset_is_its_own_rmse_and_bias() {
        let r = vec![Some([1.0f32; 3]), Some([3.0; 3])];
        let x: Vec<_> = r.iter().map(|v| v.map(|v| v.map(|c| c - 0.5))).collect();
        let e = compare(&x, &r).unwrap();
        assert!((e.rmse - 0.5).abs() < 1e-12);
        assert!((e.bias + 0.5).abs() < 1e-12);
        assert!((e.rel_bias + 0.25).abs() < 1e-12, "mean reference is 2");
        // ε = 0.01 · 2² = 0.04: (0.25/1.04 + 0.25/9.04) / 2.
        let expected = (0.25 / 1.04 + 0.25 / 9.04) / 2.0;
        assert!((e.rel_mse - expected).abs() < 1e-12);
    }

    #[test]
    fn missing_and_non_finite_texels_are_left_out() {
        let r = vec![Some([1.0f32; 3]), Some([1.0; 3]), None];
        let x = vec![Some([f32::NAN, 1.0, 1.0]), Some([2.0; 3]), Some([9.0; 3])];
        let e = compare(&x, &r).unwrap();
        assert_eq!(e.texels, 1);
        assert!((e.rmse - 1.0).abs() < 1e-12);
    }

    #[test]
    fn nothing_to_compare_is_an_error() {
        assert!(compare(&[None], &[Some([1.0; 3])]).is_err());
        assert!(compare(&[None], &[None, None]).is_err());
    }
}
