//! eHMI language (§5): what the car tells the people around it.
//!
//! Every text shown is a template or a text of the model's that passed [`check`]:
//! * at most [`EHMI_MAX_CHARS`] characters, every one in the configured [`Language`]'s
//!   character set;
//! * it states the executed maneuver in that maneuver's vocabulary ([`maneuver_vocabulary`])
//!   and no other maneuver's;
//! * it does not claim the opposite of what the car does ("please go ahead" while it goes
//!   first);
//! * it repeats no word of what people said ([`Heard`]) beyond the eHMI's own vocabulary
//!   ([`own_vocabulary`]: the words of its templates and questions, its maneuver vocabulary and
//!   [`COMMON_WORDS`]).
//!
//! Anything else is replaced by the template and logged. The tone of the templates follows the
//! detected style of the road user addressed.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::LazyLock;
use std::time::{Duration, Instant};

use concord_core::scene::{IntentAction, Style};
use concord_core::Maneuver;
use concord_ipc::wire::{WireIntent, EHMI_MAX_CHARS};
use serde::{Deserialize, Serialize};

use crate::untrusted::{fold, words, COMMON_WORDS};

/// The language of the eHMI texts: the templates, the maneuver vocabulary and the character
/// set the check accepts.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Language {
    /// English: ASCII letters and digits, the space and `. , ; : ! ? ' -`.
    #[default]
    En,
}

impl Language {
    /// True when `c` may be shown.
    pub fn allows(self, c: char) -> bool {
        match self {
            Language::En => {
                c.is_ascii_alphanumeric()
                    || matches!(c, ' ' | '.' | ',' | ';' | ':' | '!' | '?' | '\'' | '-')
            }
        }
    }
}

/// What a decision means for the others: the car gives way, or it goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stance {
    /// Stopping, waiting, or passing behind the others: they may go.
    Yielding,
    /// The car goes first.
    Proceeding,
}

/// The decision the car executes, as its texts must state it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Executed {
    pub maneuver: Maneuver,
    /// The minimum-risk fallback: the car stops.
    pub stopping: bool,
    /// The core announces that the car gives way (its plan waits for, or passes behind, every
    /// road user in conflict with it; `Decision::announce`), whatever the maneuver.
    pub gives_way: bool,
}

impl Executed {
    /// What `maneuver` announces by itself: decelerating gives way, the rest goes first.
    pub fn of(maneuver: Maneuver, stopping: bool) -> Self {
        Executed {
            maneuver,
            stopping,
            gives_way: maneuver.gives_way(),
        }
    }
    pub fn stance(self) -> Stance {
        if self.stopping || self.gives_way {
            Stance::Yielding
        } else {
            Stance::Proceeding
        }
    }
    /// The maneuver a text must state: a minimum-risk stop is a deceleration.
    pub fn stated(self) -> Maneuver {
        if self.stopping {
            Maneuver::Decelerate
        } else {
            self.maneuver
        }
    }
}

/// The words that state each maneuver, as sequences of words: a text states a maneuver when one
/// of its sequences occurs in the text's words (lower case, split at every character that is not
/// a letter or a digit).
pub fn maneuver_vocabulary(m: Maneuver) -> &'static [&'static [&'static str]] {
    match m {
        Maneuver::Accelerate => &[
            &["accelerate"],
            &["accelerating"],
            &["speed", "up"],
            &["speeding", "up"],
            &["faster"],
        ],
        Maneuver::Decelerate => &[
            &["decelerate"],
            &["decelerating"],
            &["slow", "down"],
            &["slowing"],
            &["slower"],
            &["brake"],
            &["braking"],
            &["stop"],
            &["stopping"],
        ],
        Maneuver::KeepSpeed => &[
            &["keep", "speed"],
            &["keeping", "speed"],
            &["keep", "my", "speed"],
            &["keeping", "my", "speed"],
            &["same", "speed"],
            &["steady"],
        ],
        Maneuver::TurnLeft => &[&["turn", "left"], &["turning", "left"], &["left", "turn"]],
        Maneuver::TurnRight => &[
            &["turn", "right"],
            &["turning", "right"],
            &["right", "turn"],
        ],
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
const PROCEED_CLAIMS: [&str; 15] = [
    "i am going",
    "to go first",
    "for waiting",
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

/// Why a proposed text was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    Empty,
    TooLong,
    /// A character outside the language's character set.
    BadCharacters,
    /// It does not state the executed maneuver.
    Unstated,
    /// It states another maneuver.
    OtherManeuver,
    /// It claims the opposite of what the car does, or both.
    Contradicts,
    /// It repeats a word of what somebody said.
    Echoes,
}

/// Lower-case words of an accepted-charset text, in order.
fn ordered_words(text: &str) -> Vec<String> {
    text.split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty())
        .map(str::to_ascii_lowercase)
        .collect()
}

fn states(words: &[String], m: Maneuver) -> bool {
    maneuver_vocabulary(m).iter().any(|phrase| {
        words
            .windows(phrase.len())
            .any(|w| w.iter().zip(phrase.iter()).all(|(a, b)| a == b))
    })
}

/// Accepts `text` for `executed` only when it is short, in `language`'s character set, states
/// the executed maneuver and no other, claims the stance it has, and repeats nothing `heard`
/// holds.
pub fn check(
    text: &str,
    executed: Executed,
    language: Language,
    heard: &Heard,
) -> Result<(), Refusal> {
    let t = text.trim();
    if t.is_empty() {
        return Err(Refusal::Empty);
    }
    if t.chars().count() > EHMI_MAX_CHARS {
        return Err(Refusal::TooLong);
    }
    if !t.chars().all(|c| language.allows(c)) {
        return Err(Refusal::BadCharacters);
    }
    if heard.repeats(t) {
        return Err(Refusal::Echoes);
    }
    let w = ordered_words(t);
    let stated = executed.stated();
    if Maneuver::ALL.iter().any(|m| *m != stated && states(&w, *m)) {
        return Err(Refusal::OtherManeuver);
    }
    if !states(&w, stated) {
        return Err(Refusal::Unstated);
    }
    let lower = t.to_ascii_lowercase();
    let yields = YIELD_CLAIMS.iter().any(|p| lower.contains(p));
    let proceeds = PROCEED_CLAIMS.iter().any(|p| lower.contains(p));
    match (executed.stance(), yields, proceeds) {
        (_, true, true) | (Stance::Yielding, false, true) | (Stance::Proceeding, true, false) => {
            Err(Refusal::Contradicts)
        }
        _ => Ok(()),
    }
}

/// Plans against what their maneuver says by itself (passing behind the others, or going
/// first while slowing a little): stance, maneuver, eHMI template, description.
const AGAINST_ITS_MANEUVER: [(Stance, Maneuver, &str, &str); 5] = [
    (
        Stance::Yielding,
        Maneuver::Accelerate,
        "Please go ahead; I am speeding up behind you.",
        "lets the crossing traffic go first and speeds up behind it",
    ),
    (
        Stance::Yielding,
        Maneuver::KeepSpeed,
        "Please go ahead; I am keeping my speed behind you.",
        "lets the crossing traffic go first and keeps its speed behind it",
    ),
    (
        Stance::Yielding,
        Maneuver::TurnLeft,
        "Please go ahead; I am turning left after you.",
        "lets the crossing traffic go first and turns left after it",
    ),
    (
        Stance::Yielding,
        Maneuver::TurnRight,
        "Please go ahead; I am turning right after you.",
        "lets the crossing traffic go first and turns right after it",
    ),
    (
        Stance::Proceeding,
        Maneuver::Decelerate,
        "Going first, a little slower; please wait.",
        "slows a little but passes first; others should wait",
    ),
];

/// The (template, description) of `executed` when its plan goes against its maneuver.
fn against_its_maneuver(executed: Executed) -> Option<(&'static str, &'static str)> {
    let stance = executed.stance();
    AGAINST_ITS_MANEUVER
        .iter()
        .find(|(s, m, _, _)| *s == stance && *m == executed.maneuver)
        .map(|&(_, _, template, description)| (template, description))
}

/// The template for `executed` in a tone for `style` (balanced when unknown).
pub fn template(executed: Executed, style: Option<Style>) -> &'static str {
    use Style::{Aggressive, Conservative};
    if executed.stopping {
        return "Stopping. Please go ahead carefully.";
    }
    if let Some((template, _)) = against_its_maneuver(executed) {
        return template;
    }
    match (executed.maneuver, style) {
        (Maneuver::Decelerate, Some(Aggressive)) => "Slowing down. Go ahead.",
        (Maneuver::Decelerate, Some(Conservative)) => {
            "I am slowing down for you; please go ahead, no rush."
        }
        (Maneuver::Decelerate, _) => "I am slowing down; please go ahead.",
        (Maneuver::Accelerate, Some(Aggressive)) => "Speeding up, going first. Please wait.",
        (Maneuver::Accelerate, Some(Conservative)) => {
            "I am speeding up to go first; thank you for waiting."
        }
        (Maneuver::Accelerate, _) => "I am speeding up to go first; please wait.",
        (Maneuver::KeepSpeed, Some(Aggressive)) => "Keeping my speed, going first. Please wait.",
        (Maneuver::KeepSpeed, Some(Conservative)) => {
            "I am keeping my speed to go first; thank you for waiting."
        }
        (Maneuver::KeepSpeed, _) => "I am keeping my speed and going first; please wait.",
        (Maneuver::TurnLeft, Some(Aggressive)) => "Turning left now. Please wait.",
        (Maneuver::TurnLeft, Some(Conservative)) => {
            "I am turning left first; thank you for waiting."
        }
        (Maneuver::TurnLeft, _) => "I am turning left first; please wait a moment.",
        (Maneuver::TurnRight, Some(Aggressive)) => "Turning right now. Please wait.",
        (Maneuver::TurnRight, Some(Conservative)) => {
            "I am turning right first; thank you for waiting."
        }
        (Maneuver::TurnRight, _) => "I am turning right first; please wait a moment.",
    }
}

/// What the car does, for the phrasing and reply prompts ("The car …").
pub fn describe(executed: Executed) -> &'static str {
    if executed.stopping {
        return "is stopping for safety; others may pass with care";
    }
    if let Some((_, description)) = against_its_maneuver(executed) {
        return description;
    }
    match executed.maneuver {
        Maneuver::Decelerate => "is slowing down to let the crossing traffic go first",
        Maneuver::Accelerate => "is accelerating to pass first; others should wait",
        Maneuver::KeepSpeed => "keeps its speed and passes first; others should wait",
        Maneuver::TurnLeft => "is turning left now, first; others should wait",
        Maneuver::TurnRight => "is turning right now, first; others should wait",
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

/// The text to show for `executed`: `proposed` when it passes [`check`] (and the car is not
/// stopping, which only the template announces), else the template with the refusal.
pub fn compose(
    proposed: Option<&str>,
    executed: Executed,
    style: Option<Style>,
    language: Language,
    heard: &Heard,
) -> (String, Option<Refusal>) {
    match proposed.map(|p| (p, check(p, executed, language, heard))) {
        Some((p, Ok(()))) if !executed.stopping => (p.trim().to_string(), None),
        Some((_, Err(r))) => (template(executed, style).to_string(), Some(r)),
        _ => (template(executed, style).to_string(), None),
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

/// The eHMI's own words, [`fold`]ed: those of every template, the inquiry and every
/// confirmation, the maneuver vocabulary, and [`COMMON_WORDS`]. A text may share these with a
/// message; any other word of a message it may not.
pub fn own_vocabulary() -> &'static BTreeSet<String> {
    static OWN: LazyLock<BTreeSet<String>> = LazyLock::new(|| {
        let styles = [
            None,
            Some(Style::Aggressive),
            Some(Style::Balanced),
            Some(Style::Conservative),
        ];
        let actions = [
            None,
            Some(IntentAction::Yield),
            Some(IntentAction::Proceed),
            Some(IntentAction::Accelerate),
            Some(IntentAction::Decelerate),
            Some(IntentAction::TurnLeft),
            Some(IntentAction::TurnRight),
            Some(IntentAction::Stop),
        ];
        let mut own: BTreeSet<String> = COMMON_WORDS.iter().map(|w| fold(w)).collect();
        for maneuver in Maneuver::ALL {
            for (stopping, gives_way) in [(false, false), (false, true), (true, true)] {
                for style in styles {
                    let e = Executed {
                        maneuver,
                        stopping,
                        gives_way,
                    };
                    own.extend(words(template(e, style)));
                }
            }
            for phrase in maneuver_vocabulary(maneuver) {
                own.extend(phrase.iter().map(|w| fold(w)));
            }
        }
        own.extend(words(INQUIRY));
        for a in actions {
            own.extend(words(confirmation(a)));
        }
        own
    });
    &OWN
}

/// What people said, as the eHMI check needs it: for each party (a road user, or the passenger
/// under `None`), the words of their newest messages that are not the eHMI's own. No eHMI text
/// may contain one of them. Kept apart from the dialogue and never shown to a model; bounded.
#[derive(Debug, Clone)]
pub struct Heard {
    parties: BTreeMap<Option<u32>, (u64, VecDeque<BTreeSet<String>>)>,
    messages: usize,
    max_parties: usize,
    next: u64,
}

impl Heard {
    /// Keeps the `messages` newest messages of at most `max_parties` parties (the longest
    /// silent is forgotten first).
    pub fn new(messages: usize, max_parties: usize) -> Self {
        Heard {
            parties: BTreeMap::new(),
            messages: messages.max(1),
            max_parties: max_parties.max(1),
            next: 0,
        }
    }

    /// Records a message of `party`.
    pub fn hear(&mut self, party: Option<u32>, text: &str) {
        let own = own_vocabulary();
        let new: BTreeSet<String> = words(text)
            .into_iter()
            .filter(|w| !own.contains(w))
            .collect();
        if !self.parties.contains_key(&party) && self.parties.len() >= self.max_parties {
            let oldest = self
                .parties
                .iter()
                .min_by_key(|(_, (at, _))| *at)
                .map(|(k, _)| *k);
            if let Some(k) = oldest {
                self.parties.remove(&k);
            }
        }
        self.next += 1;
        let (at, kept) = self.parties.entry(party).or_default();
        *at = self.next;
        kept.push_back(new);
        while kept.len() > self.messages {
            kept.pop_front();
        }
    }

    /// True when `text` contains a word somebody said that is not the eHMI's own.
    pub fn repeats(&self, text: &str) -> bool {
        let w = words(text);
        self.parties
            .values()
            .flat_map(|(_, kept)| kept)
            .any(|said| !said.is_disjoint(&w))
    }
}

/// A turn of the dialogue with one party.
#[derive(Debug, Clone, PartialEq)]
pub enum Turn {
    /// What the car said: a template or a text that passed [`check`].
    Car(String),
    /// What the party's message meant, as the intent parser read it (never their words).
    Heard(WireIntent),
}

/// One party of the dialogue (a road user, or the passenger under id `None`).
#[derive(Debug, Clone, Default)]
pub struct Party {
    /// Turns, oldest first.
    pub turns: VecDeque<Turn>,
    /// Style detected from their words, if strong.
    pub style: Option<Style>,
    pub last_inquiry: Option<Instant>,
    pub last_heard: Option<Instant>,
}

impl Party {
    /// The car's newest words to this party.
    pub fn car_said_last(&self) -> Option<&str> {
        self.turns.iter().rev().find_map(|t| match t {
            Turn::Car(s) => Some(s.as_str()),
            Turn::Heard(_) => None,
        })
    }
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

    fn push(&mut self, id: Option<u32>, turn: Turn, now: Instant) {
        let turns = self.turns;
        let heard = matches!(turn, Turn::Heard(_));
        let p = self.entry(id, now);
        if heard {
            p.last_heard = Some(now);
        }
        p.turns.push_back(turn);
        while p.turns.len() > turns {
            p.turns.pop_front();
        }
    }

    /// Records what the car said to a party.
    pub fn car_said(&mut self, id: Option<u32>, text: &str, now: Instant) {
        self.push(id, Turn::Car(text.to_string()), now);
    }

    /// Records what a party's message meant.
    pub fn heard(&mut self, id: Option<u32>, intent: WireIntent, now: Instant) {
        self.push(id, Turn::Heard(intent), now);
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
            self.car_said(Some(id), INQUIRY, now);
        }
        due
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const EN: Language = Language::En;

    fn doing(maneuver: Maneuver) -> Executed {
        Executed::of(maneuver, false)
    }

    fn nobody() -> Heard {
        Heard::new(4, 8)
    }

    #[test]
    fn only_the_languages_characters_are_accepted() {
        let ok = "I am slowing down; please go ahead.";
        assert_eq!(
            check(ok, doing(Maneuver::Decelerate), EN, &nobody()),
            Ok(())
        );
        for bad in [
            "I am slowing down\u{7}; please go ahead.",
            "I am slowing down; please go ahead \u{202e}",
            "I am slowing down;\u{200b} please go ahead.",
            "I am slowing down; please go ahead \u{e0041}",
            "I am slowing down; please go ahead＞",
            "I am slowing down; please go ahead <b>",
            "I am slowing down; please go ahead {}",
            "I am slowing down; please go ahead 请",
            "I am slоwing down; please go ahead.",
            "I am slowing down;\nplease go ahead.",
        ] {
            assert_eq!(
                check(bad, doing(Maneuver::Decelerate), EN, &nobody()),
                Err(Refusal::BadCharacters),
                "{bad:?}"
            );
        }
    }

    #[test]
    fn a_text_must_state_the_executed_maneuver_and_no_other() {
        let h = nobody();
        let turning = doing(Maneuver::TurnLeft);
        assert_eq!(
            check("Turning left now, please wait.", turning, EN, &h),
            Ok(())
        );
        assert_eq!(
            check("I am going first; please wait.", turning, EN, &h),
            Err(Refusal::Unstated)
        );
        assert_eq!(
            check("Turning right now, please wait.", turning, EN, &h),
            Err(Refusal::OtherManeuver)
        );
        assert_eq!(
            check("Keeping my speed and turning left; wait.", turning, EN, &h),
            Err(Refusal::OtherManeuver)
        );
        assert_eq!(
            check(
                "stop 31m accelerate 0m now",
                doing(Maneuver::Decelerate),
                EN,
                &h
            ),
            Err(Refusal::OtherManeuver)
        );
        assert_eq!(
            check(
                "I am accelerating; please wait.",
                doing(Maneuver::Accelerate),
                EN,
                &h
            ),
            Ok(())
        );
        let stopping = Executed::of(Maneuver::Decelerate, true);
        assert_eq!(check("Stopping here, go ahead.", stopping, EN, &h), Ok(()));
    }

    #[test]
    fn messages_that_contradict_the_car_are_refused() {
        let h = nobody();
        assert_eq!(
            check(
                "Keeping my speed; please go ahead!",
                doing(Maneuver::KeepSpeed),
                EN,
                &h
            ),
            Err(Refusal::Contradicts)
        );
        assert_eq!(
            check(
                "Slowing down, I'm going first",
                doing(Maneuver::Decelerate),
                EN,
                &h
            ),
            Err(Refusal::Contradicts)
        );
        assert_eq!(
            check("", doing(Maneuver::Decelerate), EN, &h),
            Err(Refusal::Empty)
        );
        assert_eq!(
            check(&"a".repeat(65), doing(Maneuver::Decelerate), EN, &h),
            Err(Refusal::TooLong)
        );
    }

    #[test]
    fn words_people_said_are_never_repeated_beyond_the_own_vocabulary() {
        let mut h = nobody();
        h.hear(
            Some(3),
            "Please go ahead, my friend. Ｖｉｓｉｔ evil.example now",
        );
        let executed = doing(Maneuver::Decelerate);
        // Its own words ("please", "go", "ahead", "now") may be shared.
        assert_eq!(
            check("I am slowing down; please go ahead now.", executed, EN, &h),
            Ok(())
        );
        for echo in [
            "Slowing down, my friend; go ahead.",
            "Slowing down; visit evil example.",
            "Slowing down; VISIT us.",
        ] {
            assert_eq!(
                check(echo, executed, EN, &h),
                Err(Refusal::Echoes),
                "{echo}"
            );
        }
        // Homoglyphs: a word said in Cyrillic letters is the same word in Latin ones.
        h.hear(None, "саrрооl");
        assert_eq!(
            check("Slowing down for the carpool; go ahead.", executed, EN, &h),
            Err(Refusal::Echoes)
        );
        // Bounded: a party's older messages are forgotten.
        let mut short = Heard::new(1, 1);
        short.hear(Some(1), "banana");
        short.hear(Some(1), "apple");
        assert!(!short.repeats("banana") && short.repeats("apple"));
        short.hear(Some(2), "cherry");
        assert!(!short.repeats("apple") && short.repeats("cherry"));
    }

    #[test]
    fn every_template_passes_its_own_check_in_every_tone_and_names_its_maneuver() {
        for maneuver in Maneuver::ALL {
            for (stopping, gives_way) in [(false, false), (false, true), (true, true)] {
                for style in [
                    None,
                    Some(Style::Aggressive),
                    Some(Style::Balanced),
                    Some(Style::Conservative),
                ] {
                    let e = Executed {
                        maneuver,
                        stopping,
                        gives_way,
                    };
                    let t = template(e, style);
                    assert_eq!(check(t, e, EN, &nobody()), Ok(()), "{t}");
                    let other = Executed {
                        gives_way: !gives_way,
                        ..e
                    };
                    if !stopping {
                        assert_eq!(
                            check(t, other, EN, &nobody()),
                            Err(Refusal::Contradicts),
                            "{t} also says the opposite"
                        );
                    }
                }
            }
        }
        assert_ne!(
            template(doing(Maneuver::Decelerate), Some(Style::Aggressive)),
            template(doing(Maneuver::Decelerate), Some(Style::Conservative))
        );
        for q in [
            INQUIRY,
            confirmation(None),
            confirmation(Some(IntentAction::Yield)),
        ] {
            assert!(q.chars().all(|c| EN.allows(c)), "{q}");
        }
    }

    #[test]
    fn compose_falls_back_to_the_template() {
        let h = nobody();
        let (t, r) = compose(
            Some("Please go ahead"),
            doing(Maneuver::KeepSpeed),
            Some(Style::Aggressive),
            EN,
            &h,
        );
        assert_eq!(t, "Keeping my speed, going first. Please wait.");
        assert_eq!(r, Some(Refusal::Unstated));
        let (t, r) = compose(
            Some(" Slowing down: after you "),
            doing(Maneuver::Decelerate),
            None,
            EN,
            &h,
        );
        assert_eq!((t.as_str(), r), ("Slowing down: after you", None));
    }

    #[test]
    fn inquiries_are_spaced_and_dialogue_is_bounded() {
        let mut d = Dialogue::new(2, 2);
        let t0 = Instant::now();
        let gap = Duration::from_secs(8);
        assert!(d.should_inquire(7, t0, gap));
        assert!(!d.should_inquire(7, t0 + Duration::from_secs(1), gap));
        assert!(d.should_inquire(7, t0 + gap, gap));
        d.heard(Some(7), WireIntent::default(), t0 + gap);
        d.car_said(Some(7), "thanks", t0 + gap);
        let p = d.party(Some(7)).unwrap();
        assert_eq!(p.turns.len(), 2);
        assert_eq!(p.car_said_last(), Some("thanks"));
        d.heard(Some(8), WireIntent::default(), t0);
        d.heard(Some(9), WireIntent::default(), t0 + gap);
        assert!(d.party(Some(8)).is_none(), "the oldest party is forgotten");
    }
}
