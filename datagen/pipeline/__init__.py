"""``datagen build``: one frame through the pipeline, the shard writer, the executors and the progress display."""
