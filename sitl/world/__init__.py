"""The simulated world: scenario ranges, seeded crowds that may walk, weather and light (all from one seed)."""
