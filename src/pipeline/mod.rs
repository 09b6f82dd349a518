//! The steps behind the commands that gather inputs from several layers and hand back what a
//! command writes or prints: a command file declares its flags, converts them into a step's
//! inputs, calls it and prints the result; the work is here, callable without a command line.
//!
//! - `preview`: clips, caches and models posed into the shots of a contact sheet
//! - `view`: the browser page of a bake, or of caches on a model's garment

pub mod preview;
pub mod view;
