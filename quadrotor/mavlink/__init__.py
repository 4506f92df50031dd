"""MAVLink pieces both sides need: signing, framing of datagrams and streams, ArduCopter's modes."""
