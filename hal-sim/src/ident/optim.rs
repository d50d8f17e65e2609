//! Global (differential evolution) and local (Levenberg-Marquardt) optimisers for identification.
