//! FlareLab's app and command line as a library, so that the UI tests (`tests/ui.rs`) drive the same
//! panels the binary shows. `main.rs` only dispatches: no arguments open the app, a subcommand runs the
//! command line. The document both edit is `flare_core::preset::Document`; both draw frames through
//! `flare_core::frame` and write files through `flare_core::output`.

pub mod app;
pub mod cli;
pub mod history;
pub mod panels;
pub mod viewport;
