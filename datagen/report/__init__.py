"""What the analyses and previews write: plots, the audit and evaluation reports, overlays, sheets, the gallery."""
