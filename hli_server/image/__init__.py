"""hli_server/image"""
