//! Scenario files (TOML): which stage effects are on, and their parameters.
