"""Re-processing a whole study: many recordings, sensor subsets and exports, one table.

``plan`` finds the recordings (folder, glob or manifest) and where each one's outputs go;
``task`` re-runs one recording in a worker (replay per subset, exports, its rows), writing
every output atomically and journalling it so a re-run after a crash or a lost worker
redoes nothing; ``executors`` spreads the tasks over a local process pool or a Dask
cluster; ``summary`` gathers the rows into ``summary.csv`` and ``summary.parquet``.
"""
