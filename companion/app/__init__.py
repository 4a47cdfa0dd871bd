"""The live flight: the mission config, the asyncio flight loop and its parts (the landing loop, commands, frame
intake, supervision, the start sequence, the operator's desk, the warning device, the live view)."""
