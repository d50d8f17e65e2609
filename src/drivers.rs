//! Converter drivers generic over embedded-hal 1.0 (`SpiDevice`, `OutputPin`): the firmware and hal-sim run the same ones.
