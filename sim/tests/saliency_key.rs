//! The core's shipped saliency key is what the fitting program gives for the scene count and
//! seed recorded in `core/src/saliency_key.rs`.

use concord_core::saliency::FITTED_KEY;
use concord_sim::saliency_fit;

#[test]
fn the_shipped_key_is_the_fit_it_records() {
    let provenance = include_str!("../../core/src/saliency_key.rs");
    let command = provenance
        .split('`')
        .find(|s| s.starts_with("concord experiment saliency"))
        .expect("the key file records its command");
    let arg = |name: &str| -> u64 {
        let words: Vec<&str> = command.split_whitespace().collect();
        let i = words.iter().position(|w| *w == name).expect(name);
        words[i + 1].parse().expect("a number")
    };
    let fit = saliency_fit::fit(&saliency_fit::dataset(
        arg("--scenes") as usize,
        arg("--seed"),
    ));
    for (shipped, fitted) in FITTED_KEY.iter().zip(&fit.key) {
        assert!(
            (shipped - fitted).abs() < 1e-3,
            "{FITTED_KEY:?} vs {:?}",
            fit.key
        );
    }
    assert!(fit.top1_fitted > fit.top1_prior);
}
