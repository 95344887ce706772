//! FlareLab's app and command line as a library, so that the UI tests (`tests/ui.rs`) drive the same
//! panels the binary shows. `main.rs` only dispatches: no arguments open the app, a subcommand runs the
//! command line.

pub mod app;
pub mod bench;
pub mod cli;
pub mod document;
pub mod history;
pub mod lut_cli;
pub mod panels;
pub mod plot;
pub mod viewport;
