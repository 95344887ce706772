//! The session: what the user edits and what is saved (the document, its undo history, the selected ghost)
//! and the one status line that says what the last action did. The window's own state (the tab, the folded
//! sections) is [`super::ui_state`]'s.
//!
//! # How it works
//! [`Session`] is the only writer of these: its fields are private, the panels edit the document through
//! [`Session::edit`] (a user's edit, committed as one undo step at the end of the gesture by
//! [`Session::commit`]), a new document arrives through [`Session::open`] (which starts a new history), and
//! undo and redo walk the history through [`Session::walk`], which says what they undid. Nothing derived from
//! the document is ever written into it (the frame source reads it; an automatic exposure stays derived), so
//! an undo always gives back exactly the document that was there (the automatic bake's LUT ghosts are
//! drawn for a document that names no LUT without it saying so: `Derived::resolved` says it in files). Every
//! action that changes state says so through
//! [`Session::say`], which replaces what the status line said before.

use flare_core::preset::Document;

use crate::history::History;

/// Which panel the right side shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Tab {
    Looks,
    Lens,
    Aperture,
    Coatings,
    Ghosts,
    Report,
    Blend,
    Shot,
}

impl Tab {
    /// Every tab, in the order of the tab bar: the one list of them.
    pub const ALL: [Tab; 8] =
        [Tab::Looks, Tab::Lens, Tab::Aperture, Tab::Coatings, Tab::Ghosts, Tab::Report, Tab::Blend, Tab::Shot];

    /// Its name on the tab bar.
    pub fn name(self) -> &'static str {
        match self {
            Tab::Looks => "Looks",
            Tab::Lens => "Lens",
            Tab::Aperture => "Aperture",
            Tab::Coatings => "Coatings",
            Tab::Ghosts => "Ghosts",
            Tab::Report => "Report",
            Tab::Blend => "Blend",
            Tab::Shot => "Shot",
        }
    }
}

pub struct Session {
    doc: Document,
    history: History,
    selected: Option<usize>,
    message: Option<String>,
}

impl Session {
    pub fn new(doc: Document) -> Self {
        Self { history: History::new(&doc), doc, selected: None, message: None }
    }

    /// The document as the user left it.
    pub fn doc(&self) -> &Document {
        &self.doc
    }

    /// The document to edit: a user's edit, one undo step with everything else changed before the gesture
    /// ends ([`Self::commit`]).
    pub fn edit(&mut self) -> &mut Document {
        &mut self.doc
    }

    /// A new document (a preset opened, dropped or restored): the history starts again from it.
    pub fn open(&mut self, doc: Document) {
        self.doc = doc;
        self.history.reset(&self.doc);
        self.selected = None;
    }

    /// Ends a gesture: the document's change since the last commit becomes one undo step.
    pub fn commit(&mut self) {
        self.history.commit(&self.doc);
    }

    /// Undo (`back`) or redo: what it undid or redid, in the document's words; `Err` with the reason when
    /// there is nothing to.
    pub fn walk(&mut self, back: bool) -> Result<String, &'static str> {
        self.history.commit(&self.doc);
        let next = if back { self.history.peek_undo() } else { self.history.peek_redo() };
        let what = next.map(|doc| crate::history::difference(&self.doc, doc)).unwrap_or_default();
        let moved = if back { self.history.undo(&mut self.doc) } else { self.history.redo(&mut self.doc) };
        match moved {
            true => Ok(what),
            false if back => Err("nothing to undo"),
            false => Err("nothing to redo"),
        }
    }

    pub fn can_undo(&self) -> bool {
        self.history.can_undo()
    }

    pub fn can_redo(&self) -> bool {
        self.history.can_redo()
    }

    /// The ghost the panels, the viewport and the ray diagram show (an index into the live flare's ghosts).
    pub fn selected(&self) -> Option<usize> {
        self.selected
    }

    pub fn select(&mut self, ghost: Option<usize>) {
        self.selected = ghost;
    }

    /// What the status line says (what the last action did, or why it failed).
    pub fn message(&self) -> Option<&str> {
        self.message.as_deref()
    }

    /// Says `text` in the status line, replacing what it said.
    pub fn say(&mut self, text: impl Into<String>) {
        self.message = Some(text.into());
    }

    /// Clears the status line (dismissed, or an action that has nothing to say).
    pub fn hush(&mut self) {
        self.message = None;
    }

    /// Takes what the status line said (to prefix it with the action that led to it).
    pub fn take_message(&mut self) -> Option<String> {
        self.message.take()
    }
}
