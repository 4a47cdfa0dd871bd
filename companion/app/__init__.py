"""The companion application: mission config, the asyncio flight loop, the flight recorder, replay."""
