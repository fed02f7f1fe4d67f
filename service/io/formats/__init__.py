"""One room per file format: readers and writers (the registry in service/io/registry.py
names them).
"""
