//! Closed-loop simulation: pipeline + mock converters + stage.
