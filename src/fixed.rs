//! Fixed-point number type for FPU-less Cortex-M (thumbv7m): the pipeline built without f32.
