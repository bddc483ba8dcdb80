//! The shipped key vector K of the saliency attention (eq. 7), one weight per query feature in
//! the order of `saliency::FEATURE_NAMES`:
//! proximity, closing speed, acceleration magnitude, conflict urgency, displacement over 1 s,
//! speed change over 1 s.
//!
//! Provenance: these are prior weights set from the features' meaning, not yet fitted. Conflict
//! urgency (3.0) and proximity (2.0) dominate, closing speed (1.5) follows, and the motion
//! features (0.5) break ties; with them the conflicting oncoming vehicle of the paper's example
//! takes most of the attention. The offline fitting program of the simulator rewrites this file
//! with weights fitted on simulated interactions and records its command and seed here.
//! Callers can override the key with `[saliency] key = [...]` in the parameter file.

/// K, dimensionless weights of the normalised query features.
pub const FITTED_KEY: [f64; crate::saliency::FEATURES] = [2.0, 1.5, 0.5, 3.0, 0.5, 0.5];
