"""Operators' and developers' tools: doctor, fuzz, QR codes, Foxglove export, the demo."""
