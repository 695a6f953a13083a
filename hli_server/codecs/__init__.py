"""hli_server/codecs"""
