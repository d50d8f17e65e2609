//! Model fitting from records (`piezo fit`): model registry, two-step Hammerstein and multivariable procedures, metrics.
