"""``datagen audit``: prove a dataset's labels are what they claim, and measure the
parallax that corrected boxes remove.

Every check recomputes from the manifests and ``features.parquet`` alone, with the
labelling context the build used (:attr:`datagen.dataset.reader.DatasetMeta.labelling`),
and names its worst offenders by file. The statistics show how far the *tight* box
centre (the perceived centre) lies from the projection of the true 3D centre, as a
function of distance, feature size and view obliqueness (paper Fig. 8).

One module per group of per-frame checks (:mod:`.manifest_checks`, :mod:`.label_lines`,
:mod:`.pose`, :mod:`.image_checks`) on their common base (:mod:`.check`), the checks of
the dataset's files (:mod:`.dataset_files`), the statistics (:mod:`.statistics`, with the
box geometry of :mod:`.box_geometry`; their typed values and JSON form: :mod:`.summary`),
the driver that feeds them shard by shard (:mod:`.driver`, over
:meth:`datagen.dataset.reader.DatasetMeta.shards`), and the frames the report draws
(:mod:`.frames`).
"""

from datagen.analysis.audit.box_geometry import feature_normals, obliqueness_deg, tight_centre_drift_px
from datagen.analysis.audit.check import DRIFT_LIMIT_PX, AuditResult, Check
from datagen.analysis.audit.driver import audit

__all__ = [
    "DRIFT_LIMIT_PX",
    "AuditResult",
    "Check",
    "audit",
    "feature_normals",
    "obliqueness_deg",
    "tight_centre_drift_px",
]
