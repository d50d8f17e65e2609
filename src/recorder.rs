//! Data recorder: fixed-size ring buffer of selected signals with a trigger.
