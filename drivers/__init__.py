"""Client-side device drivers: transports and protocols, bytes only, no physics."""
