//! The shipped key vector K of the saliency attention (eq. 7), one weight per query feature in
//! the order of `saliency::FEATURE_NAMES`:
//! proximity, closing_speed, accel_magnitude, conflict_urgency, displacement_1s, speed_change_1s.
//!
//! Provenance: fitted by `concord experiment saliency --scenes 2000 --seed 1`
//! (`concord_sim::saliency_fit`) on 2000 simulated interactions at the paper's intersection, the
//! label being the selected road user that comes closest to the CAV in the next 6 s. Top-1
//! accuracy of the most salient object: 56.3 % with the fitted key (47.9 % with the prior
//! [2.0, 1.5, 0.5, 3.0, 0.5, 0.5] it started from); mean log-likelihood -0.942 (-1.039).
//! `sim/tests/saliency_key.rs` refits and compares. Callers can override the key with
//! `[core.saliency] key = [...]` in the parameter file.

/// K, dimensionless weights of the normalised query features.
pub const FITTED_KEY: [f64; crate::saliency::FEATURES] =
    [3.8730, 0.6401, 0.1244, 2.1402, -1.9918, 0.3351];
