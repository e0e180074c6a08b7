"""Wire protocols as pure functions on bytes: TSL UMD 3.1 and 5.0, Blackmagic SDI camera control and
embedded tally. Decoders raise only :class:`~rigctl.errors.ProtocolError` and resynchronise after garbage."""
