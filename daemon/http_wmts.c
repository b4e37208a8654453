/* http_wmts — see http_wmts.h. */
#include "http_wmts.h"

#include <math.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/pixfmt.h"
#include "common/strbuf.h"

static void set_name(uint32_t T, char *out, size_t n)
{
	if (T == 256)
		snprintf(out, n, "WorldCRS84Quad");
	else
		snprintf(out, n, "WorldCRS84Quad-T%u", T);
}

/* One tile matrix set for tiles of T texels, levels 0..maxz. */
static void put_set(struct strbuf *b, uint32_t T, int maxz)
{
	char name[48];
	set_name(T, name, sizeof name);
	strbuf_printf(b, "    <TileMatrixSet>\n      <ows:Identifier>%s</ows:Identifier>\n"
	       "      <ows:SupportedCRS>urn:ogc:def:crs:OGC:1.3:CRS84</ows:SupportedCRS>\n",
	    name);
	if (T == 256)
		strbuf_printf(b, "      <WellKnownScaleSet>urn:ogc:def:wkss:OGC:1.0:GoogleCRS84Quad"
		       "</WellKnownScaleSet>\n");
	/* OGC's standardised pixel of 0.28 mm, degrees as metres on the WGS 84 equator. */
	const double m_per_deg = 2 * M_PI * 6378137.0 / 360.0;
	for (int z = 0; z <= maxz; z++) {
		double px_deg = 180.0 / ((double)T * ldexp(1, z));
		strbuf_printf(b, "      <TileMatrix>\n        <ows:Identifier>%d</ows:Identifier>\n"
		       "        <ScaleDenominator>%.10f</ScaleDenominator>\n"
		       "        <TopLeftCorner>-180 90</TopLeftCorner>\n"
		       "        <TileWidth>%u</TileWidth>\n        <TileHeight>%u</TileHeight>\n"
		       "        <MatrixWidth>%.0f</MatrixWidth>\n        <MatrixHeight>%.0f</MatrixHeight>\n"
		       "      </TileMatrix>\n",
		    z, px_deg * m_per_deg / 0.00028, T, T, ldexp(1, z + 1), ldexp(1, z));
	}
	strbuf_printf(b, "    </TileMatrixSet>\n");
}

static void put_layer(struct strbuf *b, const struct planet *p, const struct planet_layer *l,
		      const char *base)
{
	static const char *const color_fmt[] = { "png", "jpg", "webp", "tif", NULL };
	static const char *const height_fmt[] = { "png", "tif", NULL };
	static const char *const normal_fmt[] = { "png", "webp", "tif", NULL };
	const char *const *fmts = l->type == PIX_COLOR ? color_fmt
				  : l->type == PIX_HEIGHT ? height_fmt
							  : normal_fmt;
	char set[48];
	set_name(p->tile_size, set, sizeof set);
	strbuf_printf(b, "    <Layer>\n      <ows:Title>");
	strbuf_xml(b, p->name);
	strbuf_printf(b, " ");
	strbuf_xml(b, l->name);
	strbuf_printf(b, "</ows:Title>\n");
	if (p->description) {
		strbuf_printf(b, "      <ows:Abstract>");
		strbuf_xml(b, p->description);
		strbuf_printf(b, " (%s)</ows:Abstract>\n",
		    l->type == PIX_HEIGHT ? "heights: 16-bit PNG holds round(metres) + 32768, "
					    "GeoTIFF float32 metres"
					  : pix_type_name(l->type));
	}
	strbuf_printf(b, "      <ows:WGS84BoundingBox>\n        <ows:LowerCorner>-180 -90</ows:LowerCorner>\n"
	       "        <ows:UpperCorner>180 90</ows:UpperCorner>\n      </ows:WGS84BoundingBox>\n"
	       "      <ows:Identifier>");
	strbuf_xml(b, p->name);
	strbuf_printf(b, ".");
	strbuf_xml(b, l->name);
	strbuf_printf(b, "</ows:Identifier>\n      <Style isDefault=\"true\"><ows:Identifier>default"
	       "</ows:Identifier></Style>\n");
	static const char *const mime[] = { "png", "image/png", "jpg", "image/jpeg",
					    "webp", "image/webp", "tif", "image/tiff" };
	for (int i = 0; fmts[i]; i++)
		for (int k = 0; k < 8; k += 2)
			if (!strcmp(fmts[i], mime[k]))
				strbuf_printf(b, "      <Format>%s</Format>\n", mime[k + 1]);
	strbuf_printf(b, "      <TileMatrixSetLink>\n        <TileMatrixSet>%s</TileMatrixSet>\n"
	       "        <TileMatrixSetLimits>\n", set);
	for (int z = 0; z <= p->max_level; z++)
		strbuf_printf(b, "          <TileMatrixLimits><TileMatrix>%d</TileMatrix><MinTileRow>0"
		       "</MinTileRow><MaxTileRow>%.0f</MaxTileRow><MinTileCol>0</MinTileCol>"
		       "<MaxTileCol>%.0f</MaxTileCol></TileMatrixLimits>\n",
		    z, ldexp(1, z) - 1, ldexp(1, z + 1) - 1);
	strbuf_printf(b, "        </TileMatrixSetLimits>\n      </TileMatrixSetLink>\n");
	for (int i = 0; fmts[i]; i++)
		for (int k = 0; k < 8; k += 2)
			if (!strcmp(fmts[i], mime[k])) {
				strbuf_printf(b, "      <ResourceURL format=\"%s\" resourceType=\"tile\" template=\"",
				    mime[k + 1]);
				strbuf_xml(b, base);
				strbuf_printf(b, "/wmts/");
				strbuf_xml(b, p->name);
				strbuf_printf(b, "/");
				strbuf_xml(b, l->name);
				strbuf_printf(b, "/{TileMatrix}/{TileRow}/{TileCol}.%s\"/>\n", fmts[i]);
			}
	strbuf_printf(b, "    </Layer>\n");
}

char *wmts_capabilities(const struct planet_set *ps, const char *base, size_t *len)
{
	struct strbuf b = { 0 };
	strbuf_printf(&b, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
		"<Capabilities xmlns=\"http://www.opengis.net/wmts/1.0\" "
		"xmlns:ows=\"http://www.opengis.net/ows/1.1\" "
		"xmlns:xlink=\"http://www.w3.org/1999/xlink\" "
		"xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\" "
		"xsi:schemaLocation=\"http://www.opengis.net/wmts/1.0 "
		"http://schemas.opengis.net/wmts/1.0/wmtsGetCapabilities_response.xsd\" "
		"version=\"1.0.0\">\n"
		"  <ows:ServiceIdentification>\n    <ows:Title>clipmapd</ows:Title>\n"
		"    <ows:ServiceType>OGC WMTS</ows:ServiceType>\n"
		"    <ows:ServiceTypeVersion>1.0.0</ows:ServiceTypeVersion>\n"
		"  </ows:ServiceIdentification>\n  <Contents>\n");
	for (size_t i = 0; i < ps->n; i++)
		for (size_t j = 0; j < ps->planets[i]->nlayers; j++)
			put_layer(&b, ps->planets[i], &ps->planets[i]->layers[j], base);
	/* One set per tile size, as deep as the deepest planet using it. */
	for (size_t i = 0; i < ps->n; i++) {
		uint32_t T = ps->planets[i]->tile_size;
		bool seen = false;
		for (size_t k = 0; k < i; k++)
			seen |= ps->planets[k]->tile_size == T;
		if (seen)
			continue;
		int maxz = 0;
		for (size_t k = i; k < ps->n; k++)
			if (ps->planets[k]->tile_size == T && ps->planets[k]->max_level > maxz)
				maxz = ps->planets[k]->max_level;
		put_set(&b, T, maxz);
	}
	strbuf_printf(&b, "  </Contents>\n  <ServiceMetadataURL xlink:href=\"");
	strbuf_xml(&b, base);
	strbuf_printf(&b, "/wmts/1.0.0/WMTSCapabilities.xml\"/>\n</Capabilities>\n");
	return strbuf_take(&b, len);
}
