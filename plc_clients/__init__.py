"""plc_clients"""
