"""The pretend world: device emulators, source, drift, stray light, the emulated bench that
composes them with model's physics, and the emulator's truth."""
