//! Structural Bouc-Wen oscillator (003 eq. 1; the Bouc-Wen benchmark form).
