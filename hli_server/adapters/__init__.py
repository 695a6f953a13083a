"""hli_server/adapters"""
