"""Recording: the recorder that writes frames into MCAP (:mod:`.recorder`), the virtual
ADIS16364 (:mod:`.simulator`, :mod:`.noise`, :mod:`.scenario`) and the SPI driver of a real one
(:mod:`.spi`)."""
