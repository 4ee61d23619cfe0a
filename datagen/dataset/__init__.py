"""The on-disk contract of a dataset: layout, parquet schemas, YOLO lines, metadata files, the folder, the reader."""
