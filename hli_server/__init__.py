"""hli_server"""
