//! Saliency of the selected objects by scaled dot-product attention (eq. 7):
//! Attention(Q, K, V) = softmax(Q Kᵀ / √d_k) V.
//!
//! Each object's query row qᵢ is built from its state 𝓕ᵢ and its change ∇𝓕ᵢ over the history
//! ring (see [`FEATURE_NAMES`]); K is one learned key vector, so softmax over objects of
//! qᵢ·K/√d_k gives each object's saliency αᵢ (they sum to 1), and V = Q gives the attended
//! context Σ αᵢ qᵢ. The runtime only reads the key; it comes from `Params::saliency.key`,
//! whose default is [`FITTED_KEY`].

use libm::{exp, sqrt};

use crate::opm::{OpmTriplet, MAX_SELECTED};
use crate::params::{OpmParams, SaliencyParams};
use crate::scene::{History, Scene};

/// d_k: features per query row.
pub const FEATURES: usize = 6;

/// Names of the query features, in order.
pub const FEATURE_NAMES: [&str; FEATURES] = [
    "proximity",        // exp(−|pᵢ − p_ego| / 20 m)
    "closing_speed",    // −(Δp·Δv)/|Δp| / 10 m/s, clipped to [−1, 1]
    "accel_magnitude",  // |aᵢ| / 3 m/s², clipped to [0, 2]
    "conflict_urgency", // exp(−ΔTTC / ΔT_th) when in conflict, else 0
    "displacement_1s",  // |pᵢ(t) − pᵢ(t − 1 s)| / 10 m (∇𝓕ᵢ), clipped to [0, 3]
    "speed_change_1s",  // (|vᵢ(t)| − |vᵢ(t − 1 s)|) / 3 m/s (∇𝓕ᵢ), clipped to [−2, 2]
];

pub use crate::saliency_key::FITTED_KEY;

/// Attention output for one scene.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Saliency {
    /// Query rows Q, one per selected object.
    pub queries: [[f64; FEATURES]; MAX_SELECTED],
    /// αᵢ = softmax(qᵢ·K / √d_k).
    pub weights: [f64; MAX_SELECTED],
    /// Σ αᵢ qᵢ, the attended context (V = Q).
    pub context: [f64; FEATURES],
    pub n: usize,
}

/// Query row qᵢ of one object (see [`FEATURE_NAMES`]).
pub fn query(
    scene: &Scene,
    triplet: &OpmTriplet,
    object: usize,
    history: &History,
    p: &OpmParams,
) -> [f64; FEATURES] {
    let o = &triplet.objects[object];
    let a = &o.state;
    let dp = a.pos.minus(scene.ego.pos);
    let dv = a.vel.minus(scene.ego.vel);
    let dist = dp.norm();
    let closing = if dist > 1e-6 { -dp.dot(dv) / dist } else { 0.0 };
    let urgency = o
        .conflict
        .map(|c| exp(-triplet.conflicts[c as usize].delta_ttc_s / p.delta_ttc_threshold_s))
        .unwrap_or(0.0);
    let (disp, dspeed) = history
        .track(a.id)
        .and_then(|t| t.sample_ago(scene.time_s, 1.0))
        .map(|h| (a.pos.minus(h.pos).norm(), a.speed() - h.vel.norm()))
        .unwrap_or((0.0, 0.0));
    [
        exp(-dist / 20.0),
        (closing / 10.0).clamp(-1.0, 1.0),
        (a.acc.norm() / 3.0).clamp(0.0, 2.0),
        urgency,
        (disp / 10.0).clamp(0.0, 3.0),
        (dspeed / 3.0).clamp(-2.0, 2.0),
    ]
}

/// Scaled dot-product attention over given query rows with one key (eq. 7).
pub fn attend(queries: &[[f64; FEATURES]], key: &[f64; FEATURES], out: &mut Saliency) {
    let n = queries.len().min(MAX_SELECTED);
    out.n = n;
    out.context = [0.0; FEATURES];
    if n == 0 {
        return;
    }
    let scale = 1.0 / sqrt(FEATURES as f64);
    let mut logits = [0.0; MAX_SELECTED];
    for (i, q) in queries.iter().take(n).enumerate() {
        out.queries[i] = *q;
        logits[i] = q.iter().zip(key).map(|(a, b)| a * b).sum::<f64>() * scale;
    }
    softmax(&logits[..n], &mut out.weights[..n]);
    for i in 0..n {
        for (c, q) in out.context.iter_mut().zip(&out.queries[i]) {
            *c += out.weights[i] * q;
        }
    }
}

/// Computes the saliency of every selected object and stores it in the triplet.
pub fn apply(
    scene: &Scene,
    triplet: &mut OpmTriplet,
    history: &History,
    opm: &OpmParams,
    p: &SaliencyParams,
    out: &mut Saliency,
) {
    let mut q = [[0.0; FEATURES]; MAX_SELECTED];
    for (i, row) in q.iter_mut().enumerate().take(triplet.n_objects) {
        *row = query(scene, triplet, i, history, opm);
    }
    attend(&q[..triplet.n_objects], &p.key, out);
    for i in 0..triplet.n_objects {
        triplet.objects[i].saliency = out.weights[i];
    }
}

/// Numerically stable softmax: `out[i] = exp(x[i] − max) / Σ exp(x[j] − max)`.
/// Non-finite inputs give a uniform distribution.
pub fn softmax(x: &[f64], out: &mut [f64]) {
    let n = x.len().min(out.len());
    if n == 0 {
        return;
    }
    let max = x[..n].iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !max.is_finite() || x[..n].iter().any(|v| v.is_nan()) {
        out[..n].fill(1.0 / n as f64);
        return;
    }
    let mut sum = 0.0;
    for i in 0..n {
        out[i] = exp(x[i] - max);
        sum += out[i];
    }
    for v in &mut out[..n] {
        *v /= sum;
    }
}
