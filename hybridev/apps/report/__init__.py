"""Calibration reports: hold-out scoring (:mod:`.scoring`), figures (:mod:`.figures`),
HTML (:mod:`.html`) and the public builder (:mod:`.build`)."""
