//! Property and fuzz tests of the reply parser: no input makes it panic; a confidence is
//! always in [0, 1]; the confidence of a well-formed answer is exactly the probability of its
//! maneuver's tokens, whatever the tokenisation.

use concord_sidecar::reply::{string_value_span, Answer};
use concord_sidecar::schema::{maneuver_names, AdviceAnswer, IntentAnswer};
use proptest::prelude::*;

fn completion(tokens: &[(String, f64)]) -> Vec<u8> {
    let content: String = tokens.iter().map(|(t, _)| t.as_str()).collect();
    let lp: Vec<_> = tokens
        .iter()
        .map(|(t, l)| serde_json::json!({"token": t, "logprob": l}))
        .collect();
    serde_json::to_vec(&serde_json::json!({
        "choices": [{"message": {"content": content}, "finish_reason": "stop",
                     "logprobs": {"content": lp}}]
    }))
    .unwrap()
}

/// Splits `s` into pieces at the given cut fractions (on char boundaries).
fn split(s: &str, cuts: &[f64]) -> Vec<String> {
    let mut at: Vec<usize> = cuts
        .iter()
        .map(|c| {
            let mut i = (c * s.len() as f64) as usize;
            while !s.is_char_boundary(i) {
                i -= 1;
            }
            i
        })
        .collect();
    at.push(0);
    at.push(s.len());
    at.sort_unstable();
    at.dedup();
    at.windows(2).map(|w| s[w[0]..w[1]].to_string()).collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn arbitrary_bytes_never_panic(body in proptest::collection::vec(any::<u8>(), 0..400)) {
        if let Ok(a) = Answer::parse(&body) {
            let _ = AdviceAnswer::decode(&a);
            let _ = IntentAnswer::decode(&a, 0.5);
        }
    }

    #[test]
    fn arbitrary_answers_in_a_valid_envelope_never_panic(
        content in ".{0,120}",
        lps in proptest::collection::vec(-50.0f64..0.0, 0..6),
    ) {
        let cuts: Vec<f64> = lps.iter().map(|l| (-l / 50.0).clamp(0.0, 1.0)).collect();
        let pieces = split(&content, &cuts);
        let tokens: Vec<(String, f64)> =
            pieces.into_iter().zip(lps.iter().chain(std::iter::repeat(&-0.1))).map(|(t, l)| (t, *l)).collect();
        if let Ok(a) = Answer::parse(&completion(&tokens)) {
            let names = maneuver_names();
            for key in ["maneuver", "style", "action", "task"] {
                if let Some(c) = a.confidence(key, &names) {
                    prop_assert!((0.0..=1.0).contains(&c));
                }
            }
            let _ = AdviceAnswer::decode(&a);
        }
    }

    #[test]
    fn confidence_is_the_maneuver_tokens_probability_whatever_the_split(
        which in 0usize..5,
        space in any::<bool>(),
        cuts in proptest::collection::vec(0.0f64..1.0, 0..4),
        lp in -3.0f64..0.0,
    ) {
        let name = maneuver_names()[which];
        let head = if space { "{\"maneuver\": \"" } else { "{\"maneuver\":\"" };
        let tail = if space { "\" }" } else { "\"}" };
        let mut tokens: Vec<(String, f64)> = vec![(head.to_string(), 0.0)];
        let pieces = split(name, &cuts);
        let n = pieces.len() as f64;
        tokens.extend(pieces.into_iter().map(|p| (p, lp / n)));
        tokens.push((tail.to_string(), -0.3));
        let a = Answer::parse(&completion(&tokens)).unwrap();
        let advice = AdviceAnswer::decode(&a).unwrap();
        prop_assert_eq!(advice.maneuver.name(), name);
        let c = advice.confidence.unwrap();
        prop_assert!((c - lp.exp()).abs() < 1e-9, "{} vs {}", c, lp.exp());
    }

    #[test]
    fn the_locator_finds_what_serde_reads(key in "[a-z]{1,8}", value in "[ -~]{0,20}", other in "[ -~]{0,20}") {
        let json = serde_json::json!({"zz_first": other, key.clone(): value.clone()}).to_string();
        let span = string_value_span(&json, &key).unwrap();
        let raw = format!("\"{}\"", &json[span]);
        let read: String = serde_json::from_str(&raw).unwrap();
        prop_assert_eq!(read, value);
    }
}
