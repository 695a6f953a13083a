"""hli_server/engine"""
