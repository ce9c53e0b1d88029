"""Batch runs: many scenes, the same parameters, in parallel on a Dask cluster.

Every input (a stack file, a folder of frames, a raw mosaic frame; globs are expanded) is
one *scene*, segmented exactly as ``polarseg segment`` would (the task runs its job,
:func:`napari_polarseg.jobs.segment_to_folder`, so the result folder follows the
``segment`` contract) into ``OUT/<scene>/``. Then ``OUT/batch_summary.csv`` and
``OUT/batch_summary.json`` list per scene its status, timings, segment statistics and,
where the input carries ground truth (an ``.npz`` with ``labels``), the adjusted Rand
index.

Guarantees
----------
- **Atomic scenes**: a task writes into a hidden temporary folder beside the final one
  (``OUT/.<scene>.tmp-<id>``), adds the completion marker
  ``.polarseg-complete.json`` (input, parameters, every file and its size), and renames
  the folder into place. A result folder is *complete* when it holds every contract file
  plus the marker and the sizes match; an interrupted task leaves only a hidden
  temporary folder, removed by the next run.
- **Failures stay local**: a scene whose input is bad, whose task raises or whose worker
  dies is recorded with its error; the others go on.
- **Resume**: a rerun skips the scenes whose folder is complete *for the same input and
  parameters*, and redoes the failed, missing and incomplete ones (``resume=False``
  redoes everything).
- **Bounded memory**: the local cluster runs one single-threaded worker process per
  core (at most one per scene), each with a memory limit (default: the machine's memory
  shared out); only as many scenes are in flight as the cluster has threads, so a
  worker holds one scene at a time (and a worker that dies takes no queued scene down
  with it); every scene is refused up front (by the engine's memory estimate) if it
  would need more than 80 % of the smallest worker limit, instead of getting the worker
  killed. A scene whose worker dies anyway (killed, out of memory) is retried once on
  another worker, then recorded as failed.
- One batch at a time per output folder (a lock file ``OUT/.polarseg-batch.lock``).

With ``scheduler=ADDRESS`` the scenes run on an existing ``dask.distributed`` cluster;
its workers must see the inputs and the output folder under the same paths (a shared
file system) and have napari-polarseg installed. ``scheduler="inline"`` runs the scenes
one after the other in this process, without Dask (debugging, small jobs).

This package never imports napari or Qt.

The package: :mod:`~napari_polarseg.batch.plan` (scenes, output layout, completion
marker), :mod:`~napari_polarseg.batch.scene` (the task, :func:`run_scene`),
:mod:`~napari_polarseg.batch.runners` (inline and Dask) and
:mod:`~napari_polarseg.batch.run` (:func:`iter_batch`, :func:`run_batch`, the summary
tables). The names in ``__all__`` are importable from here.
"""

from .plan import (
    COLUMNS,
    LOCK_FILE,
    MARKER,
    MEMORY_SHARE,
    PARAMS_FILE,
    STATUSES,
    SUMMARY_CSV,
    SUMMARY_JSON,
    Scene,
    contract_files,
    expand_inputs,
    folder_inputs,
    is_complete,
    plan,
    plan_total,
    read_marker,
    scene_name,
)
from .run import BatchResult, iter_batch, read_summary, run_batch, write_summary
from .scene import run_scene

__all__ = [
    "COLUMNS",
    "LOCK_FILE",
    "MARKER",
    "MEMORY_SHARE",
    "PARAMS_FILE",
    "STATUSES",
    "SUMMARY_CSV",
    "SUMMARY_JSON",
    "BatchResult",
    "Scene",
    "contract_files",
    "expand_inputs",
    "folder_inputs",
    "is_complete",
    "iter_batch",
    "plan",
    "plan_total",
    "read_marker",
    "read_summary",
    "run_batch",
    "run_scene",
    "scene_name",
    "write_summary",
]
