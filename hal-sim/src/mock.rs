//! Mock converters implementing embedded-hal 1.0: SPI position ADC (AD4000-like) and SPI DAC (AD5791-like).
