//! The load report's warnings: what a glTF file holds that relume reads only in part or not
//! at all. One line per kind of loss, naming where it occurs (the first few places, then a
//! count), so a large file does not bury the report.
use std::collections::BTreeMap;

/// Places named per warning before the rest are counted.
const PLACES_NAMED: usize = 4;

#[derive(Default)]
pub struct Warnings {
    by_message: BTreeMap<String, Vec<String>>,
}

impl Warnings {
    /// Notes `message` at `place` (`materials[2] ('brick')`); repeats are named once.
    pub fn add(&mut self, message: impl Into<String>, place: &str) {
        let places = self.by_message.entry(message.into()).or_default();
        if !places.iter().any(|p| p == place) {
            places.push(place.to_string());
        }
    }

    /// `message: place, place, … and N more`, one per message, sorted.
    pub fn into_lines(self) -> Vec<String> {
        self.by_message
            .into_iter()
            .map(|(message, places)| {
                let named = places.iter().take(PLACES_NAMED).cloned().collect::<Vec<_>>().join(", ");
                match places.len().saturating_sub(PLACES_NAMED) {
                    0 => format!("{message}: {named}"),
                    more => format!("{message}: {named} and {more} more"),
                }
            })
            .collect()
    }
}
