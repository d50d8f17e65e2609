//! Command protocol of the serial port: line-based text, `no_std`, bounded parser.
