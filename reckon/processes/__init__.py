"""The long-running processes: `reckon edge`, `reckon hub` and the hub's checkpoint."""
