//! Fits the key K of the saliency attention (eq. 7) on simulated interactions, and writes it
//! as `core/src/saliency_key.rs` (`concord experiment saliency --write …`).
//!
//! **Data.** Random scenes at the paper's intersection: the CAV on its left-turn route, 2 to 6
//! road users on the other approaches at random positions, speeds and constant accelerations,
//! all kept on their lanes. The core runs on the scene's last 1.2 s at 10 Hz (so the history
//! features exist), and its OPM selection and query rows q_i are taken from the last step.
//! **Label:** the selected object that comes closest to the CAV over the next 6 s (everyone
//! continuing along their lanes, the CAV at constant speed): the road user the CAV will have
//! to deal with. Scenes where fewer than two objects are selected are skipped.
//!
//! **Fit.** K maximises the mean log-likelihood of the labels under the attention's softmax,
//! log softmax(q·K/√d_k)[label], minus `1e-3 |K|²`, by gradient ascent from [`PRIOR_KEY`]
//! (400 steps of 0.5). Deterministic for a seed.

use concord_core::saliency::FEATURES;
use concord_core::scene::{AgentState, Morphology, Scene, Vec2};
use concord_core::{DecisionCore, Params};
use concord_map::{paper, BuiltIn};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

/// The prior the fit starts from: weights set from the features' meaning (conflict urgency and
/// proximity first, closing speed next, motion features to break ties).
pub const PRIOR_KEY: [f64; FEATURES] = [2.0, 1.5, 0.5, 3.0, 0.5, 0.5];

/// One training example: the query rows of the selected objects and the label's index.
pub type Example = (Vec<[f64; FEATURES]>, usize);

/// The fit's result.
#[derive(Clone, Debug, PartialEq)]
pub struct Fit {
    pub key: [f64; FEATURES],
    pub examples: usize,
    /// Share of examples whose most salient object is the label, prior and fitted key.
    pub top1_prior: f64,
    pub top1_fitted: f64,
    /// Mean log-likelihood of the labels, prior and fitted key.
    pub loglik_prior: f64,
    pub loglik_fitted: f64,
}

const LANES: [u8; 6] = [
    paper::HDV_STRAIGHT,
    paper::EAST_LEFT,
    paper::NORTH_STRAIGHT,
    paper::SOUTH_STRAIGHT,
    paper::WEST_STRAIGHT,
    paper::EAST_RIGHT,
];

/// A road user along a lane: (lane, arc length at t = 0, speed, acceleration).
type Mover = (u8, f64, f64, f64);

fn at(m: &Morphology, mv: &Mover, t: f64, id: u32) -> AgentState {
    let (lane, s0, v0, a) = *mv;
    // Constant acceleration, never backwards.
    let t_stop = if a < 0.0 { -v0 / a } else { f64::INFINITY };
    let tt = t.min(t_stop);
    let v = (v0 + a * tt).max(0.0);
    let s = (s0 + v0 * tt + 0.5 * a * tt * tt).clamp(0.0, m.lane(lane).length());
    let (p, h, _) = m.lane(lane).to_cartesian(s, 0.0, 0);
    let mut agent = AgentState::moving(id, p, h, v);
    agent.acc = Vec2::from_angle(h).scale(if t < t_stop { a } else { 0.0 });
    agent
}

/// `n` labelled examples from `seed`.
pub fn dataset(n: usize, seed: u64) -> Vec<Example> {
    let mut rng = SmallRng::seed_from_u64(seed);
    let morph = BuiltIn::PaperIntersection.morphology();
    let stop = morph.lane(paper::CAV_LEFT).stop_s;
    // Saliency does not depend on the trajectory stage: sample little of it.
    let mut params = Params::default();
    params.trajectory.samples = 16;
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let ego: Mover = (
            paper::CAV_LEFT,
            rng.random_range(0.0..(stop - 2.0)),
            rng.random_range(4.0..10.0),
            0.0,
        );
        let others: Vec<Mover> = (0..rng.random_range(2..=6))
            .map(|_| {
                (
                    LANES[rng.random_range(0..LANES.len())],
                    rng.random_range(0.0..60.0),
                    rng.random_range(2.0..12.0),
                    rng.random_range(-1.0..1.0),
                )
            })
            .collect();
        let mut core = DecisionCore::new(params, morph).expect("valid parameters");
        // History from t = −1.2 s to 0 at 10 Hz (movers are defined at t = 0 and run backwards
        // at constant speed before it).
        let back = |mv: &Mover| (mv.0, mv.1 - 1.2 * mv.2, mv.2, 0.0);
        let mut ok = true;
        for k in 0..=12 {
            let t = k as f64 * 0.1;
            let scene_at = |mv: &Mover, id| {
                if k < 12 {
                    at(&morph, &back(mv), t, id)
                } else {
                    at(&morph, mv, 0.0, id)
                }
            };
            let mut scene = Scene::new(t, scene_at(&ego, 0), paper::CAV_LEFT);
            for (i, o) in others.iter().enumerate() {
                scene.push(scene_at(o, i as u32 + 1));
            }
            ok &= core.step(&scene, t, None).is_ok();
        }
        let triplet = core.triplet();
        let sal = core.saliency();
        if !ok || sal.n < 2 {
            continue;
        }
        // Closest approach to the CAV over the next 6 s, per selected object.
        let closest = |id: u32| {
            let mv = &others[id as usize - 1];
            (0..=60)
                .map(|k| {
                    let t = k as f64 * 0.1;
                    let e = at(&morph, &ego, t, 0).pos;
                    at(&morph, mv, t, id).pos.minus(e).norm()
                })
                .fold(f64::INFINITY, f64::min)
        };
        let label = (0..sal.n)
            .min_by(|&a, &b| {
                closest(triplet.objects[a].id).total_cmp(&closest(triplet.objects[b].id))
            })
            .expect("at least two objects");
        out.push((sal.queries[..sal.n].to_vec(), label));
    }
    out
}

fn probabilities(q: &[[f64; FEATURES]], key: &[f64; FEATURES]) -> Vec<f64> {
    let scale = 1.0 / (FEATURES as f64).sqrt();
    let logits: Vec<f64> = q
        .iter()
        .map(|r| r.iter().zip(key).map(|(a, b)| a * b).sum::<f64>() * scale)
        .collect();
    let max = logits.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let e: Vec<f64> = logits.iter().map(|l| (l - max).exp()).collect();
    let sum: f64 = e.iter().sum();
    e.iter().map(|x| x / sum).collect()
}

/// Mean log-likelihood and top-1 accuracy of `key` on `data`.
pub fn score(data: &[Example], key: &[f64; FEATURES]) -> (f64, f64) {
    let (mut ll, mut hits) = (0.0, 0);
    for (q, label) in data {
        let p = probabilities(q, key);
        ll += p[*label].max(1e-300).ln();
        let best = (0..p.len())
            .max_by(|&a, &b| p[a].total_cmp(&p[b]))
            .unwrap_or(0);
        hits += usize::from(best == *label);
    }
    let n = data.len().max(1) as f64;
    (ll / n, hits as f64 / n)
}

/// Fits K on `data` from the prior key.
pub fn fit(data: &[Example]) -> Fit {
    let scale = 1.0 / (FEATURES as f64).sqrt();
    let mut key = PRIOR_KEY;
    for _ in 0..400 {
        let mut grad = [0.0; FEATURES];
        for (q, label) in data {
            let p = probabilities(q, &key);
            for f in 0..FEATURES {
                let expected: f64 = q.iter().zip(&p).map(|(r, pi)| r[f] * pi).sum();
                grad[f] += (q[*label][f] - expected) * scale;
            }
        }
        for f in 0..FEATURES {
            key[f] += 0.5 * (grad[f] / data.len().max(1) as f64 - 2e-3 * key[f]);
        }
    }
    let (loglik_prior, top1_prior) = score(data, &PRIOR_KEY);
    let (loglik_fitted, top1_fitted) = score(data, &key);
    Fit {
        key,
        examples: data.len(),
        top1_prior,
        top1_fitted,
        loglik_prior,
        loglik_fitted,
    }
}

/// The source of `core/src/saliency_key.rs` holding `fit`, with its provenance.
pub fn key_file(fit: &Fit, command: &str) -> String {
    let names = concord_core::saliency::FEATURE_NAMES.join(", ");
    let values: Vec<String> = fit.key.iter().map(|k| format!("{k:.4}")).collect();
    format!(
        "//! The shipped key vector K of the saliency attention (eq. 7), one weight per query feature in\n\
         //! the order of `saliency::FEATURE_NAMES`:\n\
         //! {names}.\n\
         //!\n\
         //! Provenance: fitted by `{command}`\n\
         //! (`concord_sim::saliency_fit`) on {} simulated interactions at the paper's intersection, the\n\
         //! label being the selected road user that comes closest to the CAV in the next 6 s. Top-1\n\
         //! accuracy of the most salient object: {:.1} % with the fitted key ({:.1} % with the prior\n\
         //! [2.0, 1.5, 0.5, 3.0, 0.5, 0.5] it started from); mean log-likelihood {:.3} ({:.3}).\n\
         //! `sim/tests/saliency_key.rs` refits and compares. Callers can override the key with\n\
         //! `[core.saliency] key = [...]` in the parameter file.\n\
         \n\
         /// K, dimensionless weights of the normalised query features.\n\
         pub const FITTED_KEY: [f64; crate::saliency::FEATURES] =\n    [{}];\n",
        fit.examples,
        100.0 * fit.top1_fitted,
        100.0 * fit.top1_prior,
        fit.loglik_fitted,
        fit.loglik_prior,
        values.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fit_recovers_a_planted_key() {
        // Labels drawn from a known key: the fit must rank like it and beat the prior.
        let planted = [0.0, 4.0, 0.0, 0.0, 3.0, 0.0];
        let mut rng = SmallRng::seed_from_u64(3);
        let data: Vec<Example> = (0..600)
            .map(|_| {
                let q: Vec<[f64; FEATURES]> = (0..4)
                    .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
                    .collect();
                let p = probabilities(&q, &planted);
                let u: f64 = rng.random();
                let mut acc = 0.0;
                let label = p.iter().position(|pi| {
                    acc += pi;
                    u < acc
                });
                (q, label.unwrap_or(3))
            })
            .collect();
        let f = fit(&data);
        assert!(f.loglik_fitted > f.loglik_prior);
        assert!(f.key[1] > f.key[0] && f.key[1] > f.key[3], "{:?}", f.key);
        assert!(f.key[4] > f.key[2] && f.key[4] > f.key[5], "{:?}", f.key);
    }
}
