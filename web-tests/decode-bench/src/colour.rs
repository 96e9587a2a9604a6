//! zune-jpeg's colour conversion source files, as `crate::color_convert::{scalar, wasm}` (the
//! paths `wasm.rs` imports from).
#![allow(dead_code)]

#[path = "../../../vendor/zune-jpeg/src/color_convert/scalar.rs"]
pub mod scalar;
#[path = "../../../vendor/zune-jpeg/src/color_convert/wasm.rs"]
pub mod wasm;
