"""Build-time asset packing for the SITL (MakeHuman bodies): run once, its output shipped; nothing here runs in a
mission."""
