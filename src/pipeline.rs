//! The per-sample control pipeline: ADC code in, DAC code out.
