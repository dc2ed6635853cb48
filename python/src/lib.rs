//! Python module (skeleton).
