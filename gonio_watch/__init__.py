"""`gonio watch`: a live view of a run in a browser page, served on 127.0.0.1 by the standard
library's HTTP server. It follows the run directory another process writes (gonio.store's
lines, checked as they come), reduces the readings so far as `gonio reduce` does
(calibration), and relays pause, resume and abort to the scan's control channel. It sits above
gonio and calibration, below the CLI: gonio itself imports neither calibration nor this."""
