//! Undo and redo of every edit of the [`Document`].
//!
//! # How it works
//! The history keeps the last committed document and two stacks of whole documents (a document is a few
//! kilobytes; snapshots cannot drift out of step the way recorded inverse operations can). The app calls
//! [`History::commit`] at the end of every frame in which no pointer button is held: if the document differs
//! from the committed one, the committed one goes onto the undo stack. A drag of a slider or of the light is
//! therefore one step, however many frames it lasted. An edit after an undo clears the redo stack.

use flare_core::preset::Document;

/// What differs between two documents, in the words of the document's fields: the top-level fields that
/// changed (`lens`, `flare_ev`, `light_deg`, ...), a changed lens by its surfaces (`lens surface 6`), at most
/// three, for the status bar's "undid ..." and "redid ...".
pub fn difference(a: &Document, b: &Document) -> String {
    let (Ok(serde_json::Value::Object(x)), Ok(serde_json::Value::Object(y))) =
        (serde_json::to_value(a), serde_json::to_value(b))
    else {
        return "an edit".into();
    };
    let mut parts: Vec<String> = Vec::new();
    for (key, value) in &x {
        if y.get(key) == Some(value) {
            continue;
        }
        let surfaces =
            |v: &serde_json::Value| v.get("surfaces").and_then(|s| s.as_array()).cloned().unwrap_or_default();
        if key == "lens" {
            let (p, q) = (surfaces(value), surfaces(y.get(key).unwrap_or(&serde_json::Value::Null)));
            if p.len() != q.len() {
                parts.push(format!("lens: {} -> {} surfaces", p.len(), q.len()));
                continue;
            }
            let changed: Vec<String> = (0..p.len()).filter(|&k| p[k] != q[k]).map(|k| k.to_string()).collect();
            if !changed.is_empty() {
                parts.push(format!("lens surface {}", changed.join(", ")));
                continue;
            }
        }
        parts.push(key.replace('_', " "));
    }
    for key in y.keys().filter(|k| !x.contains_key(*k)) {
        parts.push(key.replace('_', " "));
    }
    match parts.len() {
        0 => "nothing".into(),
        1..=3 => parts.join(", "),
        n => format!("{} and {} more", parts[..3].join(", "), n - 3),
    }
}

/// Most undo steps kept.
pub const UNDO_LIMIT: usize = 200;

#[derive(Clone, Debug)]
pub struct History {
    committed: Document,
    undo: Vec<Document>,
    redo: Vec<Document>,
}

impl History {
    pub fn new(doc: &Document) -> Self {
        Self { committed: doc.clone(), undo: Vec::new(), redo: Vec::new() }
    }

    /// Records `doc` as one step if it changed since the last commit; true when it did.
    pub fn commit(&mut self, doc: &Document) -> bool {
        if *doc == self.committed {
            return false;
        }
        let before = std::mem::replace(&mut self.committed, doc.clone());
        self.undo.push(before);
        if self.undo.len() > UNDO_LIMIT {
            self.undo.remove(0);
        }
        self.redo.clear();
        true
    }

    /// Puts the document one step back; false when there is nothing to undo. An edit not yet committed is
    /// committed first, so it is what gets undone.
    pub fn undo(&mut self, doc: &mut Document) -> bool {
        self.commit(doc);
        let Some(before) = self.undo.pop() else { return false };
        self.redo.push(std::mem::replace(&mut self.committed, before));
        *doc = self.committed.clone();
        true
    }

    /// Re-applies the last undone step; false when there is none.
    pub fn redo(&mut self, doc: &mut Document) -> bool {
        self.commit(doc);
        let Some(after) = self.redo.pop() else { return false };
        self.undo.push(std::mem::replace(&mut self.committed, after));
        *doc = self.committed.clone();
        true
    }

    /// The document [`Self::undo`] would give back, for saying what it undoes.
    pub fn peek_undo(&self) -> Option<&Document> {
        self.undo.last()
    }

    /// The document [`Self::redo`] would give back.
    pub fn peek_redo(&self) -> Option<&Document> {
        self.redo.last()
    }

    pub fn can_undo(&self) -> bool {
        !self.undo.is_empty()
    }

    pub fn can_redo(&self) -> bool {
        !self.redo.is_empty()
    }

    /// Forgets everything (a new document was opened) and starts from `doc`.
    pub fn reset(&mut self, doc: &Document) {
        *self = Self::new(doc);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undo_and_redo_walk_the_committed_steps() {
        let mut doc = Document::default();
        let mut h = History::new(&doc);
        assert!(!h.undo(&mut doc), "nothing to undo at first");
        doc.flare_ev = 10.0;
        assert!(h.commit(&doc));
        assert!(!h.commit(&doc), "an unchanged document is no step");
        doc.flare_ev = 20.0;
        doc.light_deg = [1.0, 1.0];
        h.commit(&doc);
        assert!(h.undo(&mut doc));
        assert_eq!((doc.flare_ev, doc.light_deg), (10.0, Document::default().light_deg));
        assert!(h.undo(&mut doc));
        assert_eq!(doc, Document::default());
        assert!(h.redo(&mut doc));
        assert_eq!(doc.flare_ev, 10.0);
        // A new edit drops the redo stack.
        doc.flare_ev = 5.0;
        h.commit(&doc);
        assert!(!h.redo(&mut doc));
        assert!(h.can_undo());
    }

    #[test]
    fn an_uncommitted_edit_is_what_undo_takes_back() {
        let mut doc = Document::default();
        let mut h = History::new(&doc);
        doc.aperture.blades = 9;
        assert!(h.undo(&mut doc));
        assert_eq!(doc.aperture.blades, 6);
    }
}
