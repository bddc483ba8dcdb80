//! eHMI language (§5): what the car tells the people around it. Every message is checked
//! against what the car actually does; a message that claims otherwise ("please go ahead"
//! while accelerating into the conflict zone) is replaced by a safe template. The tone of the
//! templates follows the detected style of the road user addressed.

use std::collections::{BTreeMap, VecDeque};
use std::time::{Duration, Instant};

use concord_core::scene::{IntentAction, Style};
use concord_core::Maneuver;
use concord_ipc::wire::EHMI_MAX_CHARS;

/// What a decision means for the others: the car gives way, or it goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stance {
    /// Decelerating or stopping: the others may go.
    Yielding,
    /// Accelerating, keeping speed or turning: the car goes first.
    Proceeding,
}

impl Stance {
    /// The stance of an executed maneuver; the minimum-risk fallback (`stopping`) yields.
    pub fn of(maneuver: Maneuver, stopping: bool) -> Stance {
        if stopping || maneuver.gives_way() {
            Stance::Yielding
        } else {
            Stance::Proceeding
        }
    }
}

/// Phrases that claim the car gives way.
const YIELD_CLAIMS: [&str; 14] = [
    "go ahead",
    "after you",
    "you first",
    "you go",
    "please pass",
    "please go",
    "your turn",
    "i will wait",
    "i'll wait",
    "waiting for you",
    "slowing",
    "stopping",
    "i yield",
    "giving way",
];

/// Phrases that claim the car goes first.
const PROCEED_CLAIMS: [&str; 13] = [
    "i am going",
    "i'm going",
    "going first",
    "i will go",
    "i'll go",
    "please wait",
    "wait for me",
    "accelerat",
    "passing now",
    "turning now",
    "coming through",
    "my turn",
    "i go first",
];

/// Why a proposed message was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    Empty,
    TooLong,
    /// Characters an eHMI display should not show (control, markup).
    BadCharacters,
    /// It claims the opposite of what the car does, or both.
    Contradicts,
    /// It says neither that the car goes nor that it gives way.
    SaysNothing,
}

/// Accepts `text` for a decision of `stance` only when it is short, printable and claims
/// exactly that stance.
pub fn check(text: &str, stance: Stance) -> Result<(), Refusal> {
    let t = text.trim();
    if t.is_empty() {
        return Err(Refusal::Empty);
    }
    if t.chars().count() > EHMI_MAX_CHARS {
        return Err(Refusal::TooLong);
    }
    if t.chars()
        .any(|c| c.is_control() || matches!(c, '<' | '>' | '{' | '}' | '`' | '|' | '\\'))
    {
        return Err(Refusal::BadCharacters);
    }
    let lower = t.to_lowercase().replace('’', "'");
    let yields = YIELD_CLAIMS.iter().any(|p| lower.contains(p));
    let proceeds = PROCEED_CLAIMS.iter().any(|p| lower.contains(p));
    match (stance, yields, proceeds) {
        (_, true, true) => Err(Refusal::Contradicts),
        (Stance::Yielding, false, true) | (Stance::Proceeding, true, false) => {
            Err(Refusal::Contradicts)
        }
        (_, false, false) => Err(Refusal::SaysNothing),
        _ => Ok(()),
    }
}

/// The safe template for `stance` in a tone for `style` (balanced when unknown).
pub fn template(stance: Stance, stopping: bool, style: Option<Style>) -> &'static str {
    match (stance, stopping, style) {
        (_, true, _) => "Stopping. Please go ahead carefully.",
        (Stance::Yielding, _, Some(Style::Aggressive)) => "Slowing down. Go ahead.",
        (Stance::Yielding, _, Some(Style::Conservative)) => {
            "I am slowing down for you; please go ahead, no rush."
        }
        (Stance::Yielding, _, _) => "I am slowing down; please go ahead.",
        (Stance::Proceeding, _, Some(Style::Aggressive)) => "I am going first. Please wait.",
        (Stance::Proceeding, _, Some(Style::Conservative)) => {
            "I will go first; thank you for waiting."
        }
        (Stance::Proceeding, _, _) => "I am going first; please wait a moment.",
    }
}

/// What the car does, for the phrasing prompt ("The car …").
pub fn describe(maneuver: Maneuver, stopping: bool) -> &'static str {
    match (maneuver, stopping) {
        (_, true) => "is stopping for safety; others may pass with care",
        (Maneuver::Decelerate, _) => "is slowing down to let the crossing traffic go first",
        (Maneuver::Accelerate, _) => "is accelerating to pass first; others should wait",
        (Maneuver::KeepSpeed, _) => "keeps its speed and passes first; others should wait",
        (Maneuver::TurnLeft, _) => "is turning left now, first; others should wait",
        (Maneuver::TurnRight, _) => "is turning right now, first; others should wait",
    }
}

/// The tone for a road user of `style` (§5: tone adapts to the detected style).
pub fn tone(style: Option<Style>) -> &'static str {
    match style {
        Some(Style::Aggressive) => "short, calm and firm",
        Some(Style::Conservative) => "warm, patient and reassuring",
        _ => "polite and clear",
    }
}

/// The text to show for a decision: `proposed` when it passes [`check`], else the template.
pub fn compose(
    proposed: Option<&str>,
    stance: Stance,
    stopping: bool,
    style: Option<Style>,
) -> (String, Option<Refusal>) {
    match proposed.map(|p| (p, check(p, stance))) {
        Some((p, Ok(()))) if !stopping => (p.trim().to_string(), None),
        Some((_, Err(r))) => (template(stance, stopping, style).to_string(), Some(r)),
        _ => (template(stance, stopping, style).to_string(), None),
    }
}

/// The proactive inquiry to a road user whose intent is unknown.
pub const INQUIRY: &str = "Do you intend to pass first?";

/// The confirmatory question for a weak passenger intent (§4.3).
pub fn confirmation(action: Option<IntentAction>) -> &'static str {
    match action {
        Some(IntentAction::Accelerate | IntentAction::Proceed) => {
            "Do you want me to accelerate to pass through?"
        }
        Some(IntentAction::Yield | IntentAction::Decelerate | IntentAction::Stop) => {
            "Do you want me to slow down and let others go first?"
        }
        Some(IntentAction::TurnLeft) => "Do you want me to turn left now?",
        Some(IntentAction::TurnRight) => "Do you want me to turn right now?",
        None => "Sorry, should I hurry or take it easy?",
    }
}

/// One party of the dialogue (a road user, or the passenger under id `None`).
#[derive(Debug, Clone, Default)]
pub struct Party {
    /// Turns, oldest first: (said by the car, text).
    pub turns: VecDeque<(bool, String)>,
    /// Style detected from their words, if strong.
    pub style: Option<Style>,
    pub last_inquiry: Option<Instant>,
    pub last_heard: Option<Instant>,
}

/// Dialogue state across turns, per party, bounded.
#[derive(Debug, Clone)]
pub struct Dialogue {
    parties: BTreeMap<Option<u32>, Party>,
    turns: usize,
    max_parties: usize,
}

impl Dialogue {
    pub fn new(turns: usize, max_parties: usize) -> Self {
        Dialogue {
            parties: BTreeMap::new(),
            turns,
            max_parties,
        }
    }

    pub fn party(&self, id: Option<u32>) -> Option<&Party> {
        self.parties.get(&id)
    }

    fn entry(&mut self, id: Option<u32>, now: Instant) -> &mut Party {
        if !self.parties.contains_key(&id) && self.parties.len() >= self.max_parties {
            let oldest = self
                .parties
                .iter()
                .filter(|(k, _)| k.is_some())
                .min_by_key(|(_, p)| p.last_heard.or(p.last_inquiry))
                .map(|(k, _)| *k);
            if let Some(k) = oldest {
                self.parties.remove(&k);
            }
        }
        let p = self.parties.entry(id).or_default();
        p.last_heard.get_or_insert(now);
        p
    }

    /// Records a turn.
    pub fn say(&mut self, id: Option<u32>, by_car: bool, text: &str, now: Instant) {
        let turns = self.turns;
        let p = self.entry(id, now);
        if !by_car {
            p.last_heard = Some(now);
        }
        p.turns.push_back((by_car, text.to_string()));
        while p.turns.len() > turns {
            p.turns.pop_front();
        }
    }

    /// Records the style detected for a party.
    pub fn set_style(&mut self, id: Option<u32>, style: Option<Style>, now: Instant) {
        if style.is_some() {
            self.entry(id, now).style = style;
        }
    }

    /// True (and the inquiry recorded) when road user `id` should be asked for its intent now.
    pub fn should_inquire(&mut self, id: u32, now: Instant, interval: Duration) -> bool {
        let due = self.parties.get(&Some(id)).is_none_or(|p| {
            p.last_inquiry
                .is_none_or(|t| now.duration_since(t) >= interval)
                && p.last_heard
                    .is_none_or(|t| now.duration_since(t) >= interval)
        });
        if due {
            self.entry(Some(id), now).last_inquiry = Some(now);
            self.say(Some(id), true, INQUIRY, now);
        }
        due
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_that_contradict_the_car_are_refused() {
        assert_eq!(
            check("I am slowing down; please go ahead.", Stance::Yielding),
            Ok(())
        );
        assert_eq!(
            check("Please go ahead!", Stance::Proceeding),
            Err(Refusal::Contradicts)
        );
        assert_eq!(
            check("I'm going first, please wait", Stance::Yielding),
            Err(Refusal::Contradicts)
        );
        assert_eq!(
            check("Go ahead, I am accelerating", Stance::Yielding),
            Err(Refusal::Contradicts)
        );
        assert_eq!(check("Hello!", Stance::Yielding), Err(Refusal::SaysNothing));
        assert_eq!(
            check(&"a".repeat(65), Stance::Yielding),
            Err(Refusal::TooLong)
        );
        assert_eq!(
            check("go ahead <b>", Stance::Yielding),
            Err(Refusal::BadCharacters)
        );
    }

    #[test]
    fn every_template_passes_its_own_check_in_every_tone() {
        for stance in [Stance::Yielding, Stance::Proceeding] {
            for style in [
                None,
                Some(Style::Aggressive),
                Some(Style::Balanced),
                Some(Style::Conservative),
            ] {
                let t = template(stance, false, style);
                assert_eq!(check(t, stance), Ok(()), "{t}");
            }
        }
        assert_eq!(
            check(template(Stance::Yielding, true, None), Stance::Yielding),
            Ok(())
        );
        assert_ne!(
            template(Stance::Yielding, false, Some(Style::Aggressive)),
            template(Stance::Yielding, false, Some(Style::Conservative))
        );
    }

    #[test]
    fn compose_falls_back_to_the_template() {
        let (t, r) = compose(
            Some("Please go ahead"),
            Stance::Proceeding,
            false,
            Some(Style::Aggressive),
        );
        assert_eq!(t, "I am going first. Please wait.");
        assert_eq!(r, Some(Refusal::Contradicts));
        let (t, r) = compose(Some(" After you, friend "), Stance::Yielding, false, None);
        assert_eq!((t.as_str(), r), ("After you, friend", None));
    }

    #[test]
    fn inquiries_are_spaced_and_dialogue_is_bounded() {
        let mut d = Dialogue::new(2, 2);
        let t0 = Instant::now();
        let gap = Duration::from_secs(8);
        assert!(d.should_inquire(7, t0, gap));
        assert!(!d.should_inquire(7, t0 + Duration::from_secs(1), gap));
        assert!(d.should_inquire(7, t0 + gap, gap));
        d.say(Some(7), false, "yes", t0 + gap);
        d.say(Some(7), true, "thanks", t0 + gap);
        assert_eq!(d.party(Some(7)).unwrap().turns.len(), 2);
        d.say(Some(8), false, "hi", t0);
        d.say(Some(9), false, "hi", t0 + gap);
        assert!(d.party(Some(8)).is_none(), "the oldest party is forgotten");
    }
}
