"""The phone page served by the edge (docs/phone.md): index.html and static/ (jsQR is Apache-2.0, see its LICENSE)."""
