"""What the analyses and previews write: plots, the audit and evaluation reports, overlays, sheets, the gallery,
and a dataset in the formats other tools read (COCO, BOP)."""
