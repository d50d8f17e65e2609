//! Fault campaign over every controller mode (`piezo faults`).
