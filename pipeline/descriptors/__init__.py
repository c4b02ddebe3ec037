"""Environment descriptors of scans and of whole data sets."""
