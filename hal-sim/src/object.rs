//! Deformable object (nonlinear viscoelastic, contact beyond a gap).
