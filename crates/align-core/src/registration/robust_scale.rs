//! The residuals' scale an uncertainty report uses: the asymptotic variance of Tukey's biweight
//! M-estimator (Huber, Robust Statistics, 7.6), shared by the cloud alignment's report
//! (`pca::uncertainty`) and the robot fit's (`articulated::fit::uncertainty`).
//!
//! ```text
//! s² = [Σ ψ(r_i)² / (n - p)] / [Σ ψ'(r_i) / n]²
//! ```
//!
//! over the `n` residuals within the biweight's cutoff, `p` the parameters fitted. With Gaussian
//! residuals and no outliers `s` is their standard deviation; clutter near the surface widens it.

/// Residuals this many robust standard deviations off still count (Tukey's biweight constant:
/// 95 % efficiency for Gaussian noise).
pub(crate) const BIWEIGHT_C: f64 = 4.685;

/// The median absolute residual times this is a robust standard deviation for Gaussian noise.
pub(crate) const MAD_TO_SIGMA: f64 = 1.4826;

/// The scale of a set of signed residuals, and which of them it counted.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RobustScale {
    pub(crate) sigma_m: f64,
    /// One per residual: within the cutoff.
    pub(crate) kept: Vec<bool>,
}

/// The biweight scale of `signed` residuals fitted with `parameters` parameters, the cutoff
/// `cutoff_per_median` times their median magnitude. `Err` with the count within the cutoff
/// when it is no more than `parameters` (or no residual has weight). A noise-free fit (half its
/// residuals zero) keeps its exact residuals, at scale 0.
pub(crate) fn biweight_scale(
    signed: &[f64],
    parameters: usize,
    cutoff_per_median: f64,
) -> Result<RobustScale, usize> {
    if signed.len() <= parameters {
        return Err(signed.len());
    }
    let mut magnitudes: Vec<f64> = signed.iter().map(|r| r.abs()).collect();
    let middle = magnitudes.len() / 2;
    let (_, median, _) = magnitudes.select_nth_unstable_by(middle, f64::total_cmp);
    let cutoff_m = cutoff_per_median * *median;
    let (mut psi_squared, mut psi_slope, mut n) = (0.0, 0.0, 0usize);
    let kept: Vec<bool> = signed
        .iter()
        .map(|r| {
            let (kept, u2) = if cutoff_m > 0.0 {
                (r.abs() < cutoff_m, (r / cutoff_m).powi(2))
            } else {
                (*r == 0.0, 0.0)
            };
            if kept {
                let psi = r * (1.0 - u2).powi(2);
                psi_squared += psi * psi;
                psi_slope += (1.0 - u2) * (1.0 - 5.0 * u2);
                n += 1;
            }
            kept
        })
        .collect();
    if n <= parameters || psi_slope <= 0.0 {
        return Err(n);
    }
    Ok(RobustScale {
        sigma_m: (psi_squared / (n - parameters) as f64).sqrt() / (psi_slope / n as f64),
        kept,
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

    use super::{BIWEIGHT_C, MAD_TO_SIGMA, biweight_scale};
    use crate::rng::SplitMix64;

    #[test]
    fn gaussian_residuals_give_their_deviation_and_outliers_are_left_out() {
        let mut rng = SplitMix64::new(3);
        let sigma_m = 0.0005;
        let mut signed: Vec<f64> = (0..4000).map(|_| sigma_m * rng.gaussian()).collect();
        let clean = biweight_scale(&signed, 6, BIWEIGHT_C * MAD_TO_SIGMA).unwrap();
        assert!(
            (clean.sigma_m / sigma_m - 1.0).abs() < 0.05,
            "{}",
            clean.sigma_m
        );
        // A tenth of them 5 cm off (the floor beside a part): out of the cutoff, barely felt.
        for r in signed.iter_mut().step_by(10) {
            *r = 0.05;
        }
        let cluttered = biweight_scale(&signed, 6, BIWEIGHT_C * MAD_TO_SIGMA).unwrap();
        assert!(cluttered.kept.iter().filter(|k| !**k).count() >= 400);
        assert!(
            (cluttered.sigma_m / sigma_m - 1.0).abs() < 0.15,
            "{}",
            cluttered.sigma_m
        );
        // No more residuals than parameters: nothing to measure.
        assert_eq!(biweight_scale(&signed[..6], 6, 7.0), Err(6));
    }
}
