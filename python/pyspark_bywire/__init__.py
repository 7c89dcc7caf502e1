"""bywire's Spark data source under the name pyspark 4 looks for at start-up (a top-level
``pyspark_*`` package with a ``DefaultSource``): with the package installed,
``spark.read.format("bywire")`` works without ``bywire.spark.register(spark)``."""

from bywire.spark import BywireDataSource as DefaultSource

__all__ = ["DefaultSource"]
