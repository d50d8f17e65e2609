//! Feedforward hysteresis compensation: IMS, MBW without inversion, direct WPMBW inverse, PI inverses, multivariable IMS.
