//! Output-feedback laws from position only (000 Part III): HGO, robust virtual-control law, ADRC, PID baselines, notch.
