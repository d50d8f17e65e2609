//! Identification and model discovery (`piezo fit`, `piezo diagnose`).
