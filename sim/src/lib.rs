//! `concord-sim`: closed-loop evaluation of Concord against baselines (paper §6, Fig. 4, 7b).
//!
//! A kinematic world at 20 Hz on the core's own geometry ([`world`]), a human driver for the
//! HDV ([`driver`]), the CAV controllers behind one interface ([`controllers`]: IDM,
//! Stackelberg game, Concord logit-only, Concord with an oracle advisor), the metrics
//! ([`metrics`]), the experiment grid and its parallel runner ([`experiment`]), the figures
//! ([`plot`]) and the fitting of the saliency key ([`saliency_fit`]). Concord here is the same `DecisionCore::step` that `concord run` calls.

pub mod controllers;
pub mod driver;
pub mod experiment;
pub mod metrics;
pub mod plot;
pub mod saliency_fit;
pub mod world;
