//! Error-controlled adaptive sampling (placeholder while it is built).
